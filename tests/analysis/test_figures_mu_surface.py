"""The mu surface of the mission figure: frequency ticks in Hz, the certified peak marked where
the peak table puts it, and the figure written whole."""

import numpy as np
import pandas as pd

from oos_drake.analysis import figures


def _sweep():
    times = np.linspace(0.0, 1500.0, 6)
    hz = np.geomspace(0.005, 5.0, 13)
    T, F = np.meshgrid(times, hz, indexing="ij")
    mu = 0.2 + 0.2 * np.exp(-(np.log10(F / 0.8) ** 2) / 0.02)  # a ridge at 0.8 Hz
    rows = pd.DataFrame(
        {
            "subset": "total",
            "refined": False,
            "time [s]": T.ravel(),
            "frequency [Hz]": F.ravel(),
            "mu upper [-]": mu.ravel(),
        }
    )
    peaks = pd.DataFrame(
        {
            "subset": ["total"],
            "time [s]": [900.0],
            "frequency [Hz]": [0.8],
            "mu lower [-]": [0.39],
            "mu upper [-]": [0.4],
        }
    )
    return rows, hz, peaks


def test_mu_surface_has_hz_ticks_and_marks_the_peak():
    plt = figures.pyplot()
    sweep, hz, peaks = _sweep()
    grid = sweep.pivot_table(index="time [s]", columns="frequency [Hz]", values="mu upper [-]")
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    figures._mu_surface(fig, ax, grid, peaks)
    fig.canvas.draw()
    labels = {t.get_text() for t in ax.get_yticklabels()}
    assert {"0.01", "0.1", "1"} <= labels  # frequencies in Hz, not log10 values
    (marker,) = ax.collections[1:2]
    x, y, z = (np.asarray(v, dtype=float) for v in marker._offsets3d)
    np.testing.assert_allclose([x[0], 10 ** y[0], z[0]], [900.0, 0.8, 0.4], rtol=1e-12)
    plt.close(fig)


def test_mu_mission_figure_writes_a_png(tmp_path):
    sweep, hz, peaks = _sweep()
    path = figures.mu_mission_figure(sweep, hz, peaks, tmp_path / "mu.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
