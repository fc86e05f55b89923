r"""Tuning goals of :func:`oos_drake.control.systune.systune` (MATLAB ``TuningGoal``-like).

Each goal has a *normalized value*: ``<= 1`` means the goal is met. A goal is ``soft``
(minimized) or ``hard`` (a constraint ``<= 1``).

- :class:`WeightedGain` -- ``|| W_L T(s) W_R ||_inf`` of the closed loop ``T`` from signals
  ``inputs`` to ``outputs`` (static weights; dynamic weights belong in the plant);
- :class:`Margins` -- disk-margin goal at a loop opening, stated as gain and phase margins and
  converted to the balanced disk size (as ``TuningGoal.Margins``, skew ``sigma = 0``):

  .. math::

      \alpha = \max\Big(2\,\frac{g - 1}{g + 1},\; 2 \tan\frac{\phi_m}{2}\Big),\quad
      g = 10^{GM_{dB}/20}, \qquad
      \text{value} = \alpha\, \| S - I/2 \|_\infty,

  ``S`` the sensitivity at the opening (the transfer from a signal added there to the signal
  itself; ``S - I/2 = (S - T)/2``). The goal is met iff the disk margin
  ``1 / ||S - I/2||_inf >= alpha`` (loop at a time: ``S_ii - 1/2`` of each channel with the
  other loops closed; ``multiloop=True``: ``sigma_max(S - I/2)``, an upper bound of the
  ``mu`` of the multiloop disk margin, so meeting it guarantees the multiloop margin; MATLAB
  adds D-scalings that make it less conservative);
- :class:`Poles` -- closed-loop poles with damping ``>= min_damping`` and natural frequency
  ``<= max_frequency`` (discrete poles through ``s = ln(z) / T_s``), value
  ``max_poles max((1 - zeta) / (1 - zeta_min), |s| / omega_max)``;
- :class:`Variance` -- ``||T||_2 / max_std``: the standard deviation of ``outputs`` for unit
  white noise on ``inputs`` (continuous loops need ``D_cl = 0``).

Closed-loop stability of every model is always required (as systune).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WeightedGain", "Margins", "Poles", "Variance", "disk_alpha"]


def _names(names) -> tuple[str, ...]:
    return (names,) if isinstance(names, str) else tuple(names)


def _check_kind(goal) -> None:
    if goal.kind not in ("soft", "hard"):
        raise ValueError(f"goal {goal.label!r}: kind must be 'soft' or 'hard', got {goal.kind!r}")


@dataclass(frozen=True)
class WeightedGain:
    """``||W_L T W_R||_inf <= 1`` for the closed loop ``T`` from ``inputs`` to ``outputs``.

    Parameters
    ----------
    inputs, outputs : str or sequence of str
        Signal names (a name ``"d"`` also matches channels ``"d[0]", "d[1]", ...``). An input
        that some block produces is an additive injection point there (an analysis point).
    left_weight, right_weight : float or array_like, optional
        Static ``W_L`` (outputs side) and ``W_R`` (inputs side): scalars, vectors (diagonal) or
        matrices [-].
    kind : str
        ``"soft"`` or ``"hard"``.
    name : str, optional
        Label in results and messages.
    """

    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    left_weight: object = 1.0
    right_weight: object = 1.0
    kind: str = "soft"
    name: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "inputs", _names(self.inputs))
        object.__setattr__(self, "outputs", _names(self.outputs))
        _check_kind(self)

    @property
    def label(self) -> str:
        return self.name or f"WeightedGain({','.join(self.inputs)}->{','.join(self.outputs)})"


def disk_alpha(gain_margin_db: float, phase_margin_deg: float) -> float:
    """Balanced disk size ``alpha`` that guarantees both margins (``TuningGoal.Margins``).

    Parameters
    ----------
    gain_margin_db : float
        Required gain margin [dB] (``> 0``).
    phase_margin_deg : float
        Required phase margin [deg] (``0 <= PM < 180``).

    Returns
    -------
    float
        ``max(2 (g - 1)/(g + 1), 2 tan(PM/2))`` [-], the inverse of
        :func:`oos_drake.control.margins.disk_gain_phase`.
    """
    g = 10.0 ** (gain_margin_db / 20.0)
    return float(max(2 * (g - 1) / (g + 1), 2 * np.tan(np.radians(phase_margin_deg) / 2)))


@dataclass(frozen=True)
class Margins:
    """Gain and phase margins at a loop opening, through the balanced disk margin.

    Parameters
    ----------
    loop_opening : str or sequence of str
        Signals where the loop is opened: plant inputs driven by the controller or
        measurements read by it (a name matches its channels ``name[i]``).
    gain_margin_db : float
        Required gain margin [dB].
    phase_margin_deg : float
        Required phase margin [deg].
    multiloop : bool
        ``False``: loop at a time (each channel, the others closed); ``True``: all channels
        varying at once (``sigma_max`` bound, conservative).
    kind : str
        ``"soft"`` or ``"hard"``.
    name : str, optional
    """

    loop_opening: tuple[str, ...]
    gain_margin_db: float = 6.0
    phase_margin_deg: float = 30.0
    multiloop: bool = False
    kind: str = "hard"
    name: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "loop_opening", _names(self.loop_opening))
        _check_kind(self)
        if not (self.gain_margin_db > 0 and 0 <= self.phase_margin_deg < 180):
            raise ValueError(
                f"goal {self.label!r}: needs gain_margin_db > 0 and 0 <= phase_margin_deg < 180"
            )
        if self.alpha >= 2:
            # ||S - 1/2||_inf >= 1/2 at high frequency for a strictly proper loop
            raise ValueError(
                f"goal {self.label!r} cannot be met: {self.gain_margin_db} dB / "
                f"{self.phase_margin_deg} deg needs a disk margin {self.alpha:.3g} >= 2"
            )

    @property
    def alpha(self) -> float:
        """Required balanced disk margin [-] (:func:`disk_alpha`)."""
        return disk_alpha(self.gain_margin_db, self.phase_margin_deg)

    @property
    def label(self) -> str:
        return self.name or f"Margins({','.join(self.loop_opening)})"


@dataclass(frozen=True)
class Poles:
    """Closed-loop poles: damping ``>= min_damping``, natural frequency ``<= max_frequency``.

    Parameters
    ----------
    min_damping : float
        Minimum damping ratio ``zeta`` [-] (``0 <= zeta < 1``).
    max_frequency : float
        Maximum natural frequency ``|s|`` [rad/s] (``inf``: none).
    kind : str
    name : str, optional
    """

    min_damping: float = 0.0
    max_frequency: float = np.inf
    kind: str = "soft"
    name: str | None = None

    def __post_init__(self):
        _check_kind(self)
        if not 0 <= self.min_damping < 1:
            raise ValueError(
                f"goal {self.label!r} cannot be met: min_damping must be in [0, 1), "
                f"got {self.min_damping}"
            )
        if not self.max_frequency > 0:
            raise ValueError(f"goal {self.label!r}: max_frequency must be > 0 [rad/s]")

    @property
    def label(self) -> str:
        return self.name or "Poles"


@dataclass(frozen=True)
class Variance:
    """``||T||_2 <= max_std``: output standard deviation for unit-intensity white noise.

    Parameters
    ----------
    inputs, outputs : str or sequence of str
        Noise inputs and measured outputs (signal names).
    max_std : float
        Allowed standard deviation [output unit] (continuous time: per unit power spectral
        density of the noise; discrete: per unit variance).
    kind : str
    name : str, optional
    """

    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    max_std: float = 1.0
    kind: str = "soft"
    name: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "inputs", _names(self.inputs))
        object.__setattr__(self, "outputs", _names(self.outputs))
        _check_kind(self)
        if not self.max_std > 0:
            raise ValueError(f"goal {self.label!r}: max_std must be > 0")

    @property
    def label(self) -> str:
        return self.name or f"Variance({','.join(self.inputs)}->{','.join(self.outputs)})"
