"""What the commands show: a training's live display and the other commands' tables."""
