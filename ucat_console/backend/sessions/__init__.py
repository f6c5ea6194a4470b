"""Session recording and reading (MCAP), index, repair and export."""
