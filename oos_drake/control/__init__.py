"""oos_drake.control."""
