"""``oos robust`` commands: bounds from files, clear errors."""

import numpy as np
from scipy.io import savemat

from oos_drake.cli import main


def test_mussv_from_mat_file(tmp_path, capsys):
    M = np.array([[2.0, 2.0], [-1.0, -1.0]])  # S&P Example 8.5: mu = 3 for two complex scalars
    savemat(tmp_path / "case.mat", {"M": M, "blk": np.array([[1, 1], [1, 1]])})
    out = tmp_path / "bounds.npz"
    assert main(["robust", "mussv", str(tmp_path / "case.mat"), "--out", str(out)]) == 0
    assert "peak: mu in [3, 3" in capsys.readouterr().out
    with np.load(out) as data:
        assert abs(float(data["upper"]) - 3.0) < 1e-3


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
