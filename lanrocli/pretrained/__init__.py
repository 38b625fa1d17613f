"""Trained agents that ship with lanro, one folder each (a checkpoint of the policy alone): see
:mod:`lanrocli.train.pretrained`."""
