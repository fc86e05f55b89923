"""Attitude control design (paper section 3): weighted interconnection, baseline, synthesis.

``from oos_drake.control import weighted_interconnection, baseline_gains, synthesize`` gives the
main entry points:

- :func:`weighted_interconnection` -- Fig. controldesign around a (batched) 3x3 plant
  ``T_ext,G1 -> wdot`` (sensors, wheels, roll-off, noise/disturbance/performance weights);
- :func:`baseline_gains` -- ``K_att = [w^2 J_tot, 2 xi w J_tot]``;
- :func:`synthesize` -- multi-model structured H-infinity synthesis of the 3x6 static gain over
  configurations and real uncertainty (nonsmooth BFGS-SQP, worst-case search);
- :func:`peak_gain` -- batched H-infinity norms of model arrays (from :mod:`oos_drake.robust`);
- :class:`LoopResponse` -- closed-loop responses from the plant's modal form (the fast path of
  every gamma evaluation: closed-loop eigenvalues only, no eigenvectors);
- :func:`close_loop` -- the uncertain closed loop with Delta_add and Delta_mul (the analysis');
- :func:`write_synthesis` -- controller JSON, closed-loop arrays (.npz/.mat), per-model tables;
- :func:`systune` -- structured tuning of any controller (:class:`TunableGain`,
  :class:`TunablePID`, :class:`TunableSS`, :class:`FixedBlock`) against soft and hard goals
  (:class:`WeightedGain`, :class:`Margins`, :class:`Poles`, :class:`Variance`) over a plant array.

This package never imports pydrake (``oos synth --plant drake`` imports
:mod:`oos_drake.multibody.synthesis_plants` lazily from :mod:`oos_drake.app.synth`).
"""

from oos_drake.control.analysis_model import close_loop, uncertain_plant
from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.components import DesignSpecification
from oos_drake.control.goals import Margins, Poles, Variance, WeightedGain
from oos_drake.control.interconnection import WeightedInterconnection, weighted_interconnection
from oos_drake.control.loop_response import LoopResponse, LoopSigma
from oos_drake.control.plants import PlantArray, UncertainParameter, from_lfr
from oos_drake.control.report import write_synthesis
from oos_drake.control.statespace import BatchedStateSpace, connect
from oos_drake.control.synthesis import SynthesisOptions, SynthesisResult, synthesize
from oos_drake.control.systune import GoalValue, SystuneOptions, TuningResult, systune
from oos_drake.control.tunable import FixedBlock, TunableGain, TunablePID, TunableSS
from oos_drake.robust.peak_gain import PeakGain, peak_gain

__all__ = [
    "BatchedStateSpace",
    "DesignSpecification",
    "FixedBlock",
    "GoalValue",
    "Margins",
    "Poles",
    "SystuneOptions",
    "TunableGain",
    "TunablePID",
    "TunableSS",
    "TuningResult",
    "Variance",
    "WeightedGain",
    "LoopResponse",
    "LoopSigma",
    "PeakGain",
    "PlantArray",
    "SynthesisOptions",
    "SynthesisResult",
    "UncertainParameter",
    "WeightedInterconnection",
    "baseline_gains",
    "close_loop",
    "connect",
    "from_lfr",
    "inertia_from_plant",
    "peak_gain",
    "synthesize",
    "systune",
    "uncertain_plant",
    "weighted_interconnection",
    "write_synthesis",
]
