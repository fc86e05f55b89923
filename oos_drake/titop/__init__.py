"""oos_drake.titop."""
