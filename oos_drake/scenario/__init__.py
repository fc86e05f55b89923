"""oos_drake.scenario."""
