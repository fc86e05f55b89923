"""oos_drake.lfr."""
