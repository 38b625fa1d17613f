"""What has been run, read back from run folders: learning-curve plots and ``lanro report``'s aggregates
across runs, with bootstrap intervals."""
