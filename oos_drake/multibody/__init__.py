"""oos_drake.multibody."""
