"""oos_drake: from flexible multi-body spacecraft data to a certified attitude controller.

Data flows one way:
physical data -> LFR model -> analysis/synthesis -> campaign -> tables & figures.

Subpackages
-----------
lfr        uncertain blocks and the LFR algebra (numpy/scipy/python-control only)
titop      TITOP building blocks returning LFRs
scenario   the paper's spacecraft data, geometry, mission timeline and model assembly
multibody  everything that imports pydrake
robust     mussv, robstab, wcgain, H-infinity norm, model-array sweeps
control    weights, sensors, actuators, baseline and structured H-infinity synthesis
campaign   campaign specs, samplers, runner, executors, result tables, reports
"""

__version__ = "0.1.0"
