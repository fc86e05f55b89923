"""Effect of each uncertainty set on the open-loop channel ``T_ext,G1{1} -> wdot{1}`` (paper Fig.
unc_sensitivity): random samples of each subset (MATLAB ``usample`` semantics, the other blocks
nominal) at one configuration.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: Columns of the open-loop samples table.
OPEN_LOOP_COLUMNS = ["subset", "sample", "frequency [Hz]", "gain [dB]"]


def uncertainty_effects(
    plant_hat, subsets: dict, omega, *, samples: int = 20, rng: np.random.Generator, channel=(0, 0)
) -> pd.DataFrame:
    """Gains of one plant channel for random samples of each uncertainty subset.

    Parameters
    ----------
    plant_hat : LFR
        Uncertain plant ``T -> wdot`` (3x3) with ``Delta_tot`` (configuration substituted).
    subsets : dict
        Subset name -> block names.
    omega : array_like
        Frequencies [rad/s].
    samples : int
        Samples per subset (sample ``-1`` is the nominal).
    rng : numpy.random.Generator
        Source of the samples.
    channel : (int, int)
        ``(output, input)`` of the channel (default ``wdot_x <- T_x``).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`OPEN_LOOP_COLUMNS` (gain in dB of [(rad/s^2)/(N m)]).
    """
    from oos_drake.lfr import usample

    sys = plant_hat[channel[0], channel[1]]
    omega = np.asarray(omega, dtype=float)
    hz = omega / (2 * np.pi)
    frames = []
    nominal = np.abs(sys.nominal.freqresp(omega)[..., 0, 0])
    frames.append(
        pd.DataFrame(
            {
                "subset": "nominal",
                "sample": -1,
                "frequency [Hz]": hz,
                "gain [dB]": 20 * np.log10(np.maximum(nominal, 1e-300)),
            }
        )
    )
    for name, members in subsets.items():
        models, _ = usample(sys, samples, rng, names=list(members))
        H = np.abs(models.nominal.freqresp(omega)[..., 0, 0])  # (samples, F)
        for k in range(samples):
            frames.append(
                pd.DataFrame(
                    {
                        "subset": name,
                        "sample": k,
                        "frequency [Hz]": hz,
                        "gain [dB]": 20 * np.log10(np.maximum(H[k], 1e-300)),
                    }
                )
            )
    return pd.concat(frames, ignore_index=True)[OPEN_LOOP_COLUMNS]
