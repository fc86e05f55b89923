"""``oos robust`` commands: bounds from files, clear errors."""

import numpy as np
import pytest
from scipy.io import savemat

from oos_drake.app.main import main


def test_mussv_from_mat_file(tmp_path, capsys):
    M = np.array([[2.0, 2.0], [-1.0, -1.0]])  # S&P Example 8.5: mu = 3 for two complex scalars
    savemat(tmp_path / "case.mat", {"M": M, "blk": np.array([[1, 1], [1, 1]])})
    out = tmp_path / "bounds.npz"
    assert main(["robust", "mussv", str(tmp_path / "case.mat"), "--out", str(out)]) == 0
    assert "peak: mu in [3, 3" in capsys.readouterr().out
    with np.load(out) as data:
        assert abs(float(data["upper"]) - 3.0) < 1e-3


def test_mussv_out_is_written_whole_or_not_at_all(tmp_path, capsys, monkeypatch):
    """``--out`` as ``np.savez`` names it (``.npz`` appended), through a temporary file: a
    write that fails half-way leaves neither the file nor the temporary one."""
    savemat(tmp_path / "case.mat", {"M": np.eye(2), "blk": np.array([[1, 1], [1, 1]])})
    assert main(["robust", "mussv", str(tmp_path / "case.mat"), "--out", str(tmp_path / "b")]) == 0
    with np.load(tmp_path / "b.npz") as data:
        assert set(data.files) == {"upper", "lower", "delta", "D_left", "D_right", "G"}

    def broken(stream, **arrays):
        stream.write(b"PK partial")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", broken)
    out = tmp_path / "c.npz"
    with pytest.raises(OSError, match="disk full"):
        main(["robust", "mussv", str(tmp_path / "case.mat"), "--out", str(out)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.npz", "case.mat"]


def test_hinfnorm_from_npz(tmp_path, capsys):
    np.savez(tmp_path / "p.npz", A=[[-1.0]], B=[[1.0]], C=[[2.0]], D=[[0.0]])
    assert main(["robust", "hinfnorm", str(tmp_path / "p.npz")]) == 0
    assert "||G||_inf = 2 " in capsys.readouterr().out


def test_bad_files_give_exit_status_2(tmp_path, capsys):
    np.savez(tmp_path / "bad.npz", M=np.ones((2, 2)))
    assert main(["robust", "mussv", str(tmp_path / "bad.npz")]) == 2
    assert "missing variable" in capsys.readouterr().err
    np.savez(tmp_path / "bad2.npz", M=np.ones((3, 2)), blk=np.array([[1, 1], [1, 1]]))
    assert main(["robust", "mussv", str(tmp_path / "bad2.npz")]) == 2
    assert "does not match blk" in capsys.readouterr().err


def test_mussv_reads_a_matlab_model_array_batch_last(tmp_path, capsys):
    """MATLAB stores ``M(:, :, k)``: a 3 x 3 x 5 file is five 3 x 3 matrices, not three 3 x 5.

    One full complex 3 x 3 block: mu is the largest singular value (closed form).
    """
    rng = np.random.default_rng(3)
    stack = rng.standard_normal((5, 3, 3)) + 1j * rng.standard_normal((5, 3, 3))
    as_matlab = np.moveaxis(stack, 0, -1)  # M(:, :, k) = stack[k]
    assert as_matlab.shape == (3, 3, 5)
    savemat(tmp_path / "array.mat", {"M": as_matlab, "blk": np.array([[3, 3]])})
    out = tmp_path / "bounds.npz"
    assert main(["robust", "mussv", str(tmp_path / "array.mat"), "--out", str(out)]) == 0
    assert "5 matrix(es)" in capsys.readouterr().out
    sigma = np.linalg.norm(stack, ord=2, axis=(-2, -1))
    with np.load(out) as data:
        np.testing.assert_allclose(data["upper"], sigma, rtol=1e-6)
        np.testing.assert_allclose(data["lower"], sigma, rtol=1e-6)


def test_hinfnorm_reads_a_matlab_model_array(tmp_path, capsys):
    """Two first-order systems ``c / (s + a)`` stored MATLAB-style: norms ``|c| / a``."""
    a, c = np.array([1.0, 4.0]), np.array([2.0, 2.0])
    A = np.moveaxis(-a.reshape(2, 1, 1), 0, -1)  # 1 x 1 x 2
    B = np.ones((1, 1, 2))
    C = np.moveaxis(c.reshape(2, 1, 1), 0, -1)
    D = np.zeros((1, 1, 2))
    savemat(tmp_path / "p.mat", {"A": A, "B": B, "C": C, "D": D})
    assert main(["robust", "hinfnorm", str(tmp_path / "p.mat")]) == 0
    text = capsys.readouterr().out
    assert "[0] ||G||_inf = 2 " in text and "[1] ||G||_inf = 0.5 " in text


def test_robstab_writes_the_mu_sweep_table(tmp_path, capsys):
    """``--out`` writes the one sweep table; a complex scalar's mu is |0.5 P / (1 + P)|."""
    import control
    import pandas as pd

    from oos_drake.lfr import feedback, ucomplex
    from oos_drake.robust.tables import GUARANTEE_COLUMNS, SWEEP_COLUMNS

    loop = feedback(ucomplex("c", 1.0, 0.5) * control.tf([4.0], [1.0, 2.0, 1.0]), 1)
    loop.to_npz(tmp_path / "loop.npz")
    out = tmp_path / "mu.csv"
    assert main(["robust", "robstab", str(tmp_path / "loop.npz"), "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert list(table.columns) == SWEEP_COLUMNS + GUARANTEE_COLUMNS
    P = 4.0 / (2j * np.pi * table["frequency [Hz]"].to_numpy() + 1.0) ** 2
    np.testing.assert_allclose(table["mu upper [-]"], np.abs(0.5 * P / (1 + P)), rtol=1e-6)
    assert main(["robust", "robstab", str(tmp_path / "loop.npz"), "--out", "mu.txt"]) == 2
    assert "expected a .csv or .parquet" in capsys.readouterr().err


def test_sweep_of_a_stored_model_array(tmp_path, capsys):
    """``oos robust sweep`` on a stored LFR model array: one table row per model and
    frequency, equal to the closed form |0.5 g P / (1 + g P)| of a complex scalar block."""
    import control
    import pandas as pd

    from oos_drake.lfr import feedback, ucomplex, ureal, usubs
    from oos_drake.robust.tables import GUARANTEE_COLUMNS, SWEEP_COLUMNS

    gains = np.array([0.8, 1.25])
    P = control.tf([4.0], [1.0, 2.0, 1.0])
    g = ureal("g", 1.0, plusminus=0.5)
    arr = usubs(feedback(ucomplex("c", 1.0, 0.5) * g * P, 1), {"g": gains})
    arr.to_npz(tmp_path / "loops.npz")
    out = tmp_path / "mu.parquet"
    assert main(["robust", "sweep", str(tmp_path / "loops.npz"), "--out", str(out)]) == 0
    table = pd.read_parquet(out)
    assert list(table.columns) == SWEEP_COLUMNS + GUARANTEE_COLUMNS
    assert sorted(table["model"].unique()) == [0, 1]
    gP = (
        gains[table["model"].to_numpy()]
        * 4.0
        / ((2j * np.pi * table["frequency [Hz]"].to_numpy() + 1.0) ** 2)
    )
    mu = np.abs(0.5 * gP / (1 + gP))
    np.testing.assert_allclose(table["mu upper [-]"], mu, rtol=1e-6)
    assert np.all(table["mu lower [-]"] <= mu * (1 + 1e-9))
    text = capsys.readouterr().out
    assert "total [1]: peak mu in" in text and "on the whole frequency axis" in text
    assert main(["robust", "sweep", str(tmp_path / "loops.npz"), "--out", "mu.txt"]) == 2
