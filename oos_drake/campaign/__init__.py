"""oos_drake.campaign."""
