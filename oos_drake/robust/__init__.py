"""oos_drake.robust."""
