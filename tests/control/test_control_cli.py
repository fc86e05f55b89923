"""``oos synth``: writes the controller, the closed-loop array and the per-model table."""

import json

import numpy as np
import pandas as pd
import scipy.io

from oos_drake.app.main import main


def test_synth_writes_every_output(tmp_path):
    out = tmp_path / "synth"
    status = main(
        [
            "synth",
            "--plant",
            "synthetic",
            "--configurations",
            "3",
            "--restarts",
            "0",
            "--max-iterations",
            "5",
            "--worst-case-rounds",
            "0",
            "--out",
            str(out),
        ]
    )
    assert status == 0
    record = json.loads((out / "controller.json").read_text())
    K_p = np.array(record["controller"]["K_p"]["value"])
    assert K_p.shape == (3, 3) and record["controller"]["K_p"]["unit"] == "N m/rad"
    assert len(record["model_sha256"]) == 64
    assert record["gamma"] <= record["gamma_baseline"]
    table = pd.read_parquet(out / "models.parquet")
    assert len(table) == 3 and {"gamma [-]", "peak frequency [Hz]", "time [s]"} <= set(
        table.columns
    )
    assert np.isclose(table["gamma [-]"].max(), record["gamma"], rtol=1e-12)
    npz = np.load(out / "closed_loop.npz")
    assert npz["A"].shape[0] == 3 and npz["B"].shape[-1] == 9 and npz["C"].shape[-2] == 6
    mat = scipy.io.loadmat(out / "closed_loop.mat")
    # MATLAB layout: model k is A(:, :, k)
    assert mat["A"].shape == npz["A"].shape[1:] + (3,)
    for k in range(3):
        np.testing.assert_allclose(mat["A"][:, :, k], npz["A"][k])
        np.testing.assert_allclose(mat["D"][:, :, k], npz["D"][k])
    assert pd.read_csv(out / "models.csv").shape[0] == 3
