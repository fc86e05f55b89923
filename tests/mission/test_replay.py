"""``oos campaign replay``: HTML 3D replay of one run of a tiny Drake campaign (6 s window)."""

from __future__ import annotations

import base64
import re
import textwrap

import numpy as np
import pandas as pd
import pytest

from oos_drake.campaign.spec import SPEC_DIRECTORY

pytestmark = pytest.mark.drake

msgpack = pytest.importorskip("msgpack")

CAMPAIGNS = SPEC_DIRECTORY
LOG_RATE = 2.0  # [Hz]
BEFORE, AFTER = 2.0, 4.0  # [s] around the capture (255 s)

SPEC = textwrap.dedent(
    f"""
    scenario = "paper"
    name = "tiny_replay"
    n_runs = 2
    random_seed = 7
    sampler = "monte-carlo"
    metrics = ["ape", "peak_torque"]

    [simulator]
    name = "oos_drake.campaign.drake_simulator:make_simulator"
    options = {{ control_rate = 10.0, log_rate = {LOG_RATE} }}

    [window]
    kind = "event"
    event = "capture"
    before = {BEFORE}
    after = {AFTER}

    [dispersions]
    m_RH2 = {{ distribution = "uniform" }}  # the scenario's declared range
    phi0_x = {{ distribution = "normal", mean = 0.0, std = 2.0e-3 }}
    phi0_y = {{ distribution = "normal", mean = 0.0, std = 2.0e-3 }}
    w0_z = {{ distribution = "normal", mean = 0.0, std = 2.0e-4 }}

    [requirements]
    ape = {{ max = 0.0079 }}

    [timeseries]
    keep = "all"
    """
)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from oos_drake.campaign.runner import run_campaign

    root = tmp_path_factory.mktemp("replay")
    spec = root / "tiny.toml"
    spec.write_text(SPEC)
    run_campaign(spec, root / "campaign", workers=1, progress=False)
    return root / "campaign"


def _commands(html: str) -> list[dict]:
    """The Meshcat commands a static HTML page replays (base64 msgpack data URLs)."""
    blobs = re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)
    return [msgpack.unpackb(base64.b64decode(blob), strict_map_key=False) for blob in blobs]


def _animation(html: str) -> dict[str, dict]:
    animations = [c for c in _commands(html) if c.get("type") == "set_animation"]
    assert len(animations) == 1
    return {a["path"]: a["clip"] for a in animations[0]["animations"]}


def _track(clip: dict, name: str) -> list[dict]:
    return next(t["keys"] for t in clip["tracks"] if t["name"] == name)


def test_replay_writes_scene_and_animation_matching_the_run(campaign):
    from oos_drake.campaign import store
    from oos_drake.campaign.replay import replay_case, replay_path

    run_id = 1
    result = replay_case(campaign, run_id)
    assert result.speed == 1.0  # a 6 s window plays in real time by default
    path = replay_path(campaign, run_id)
    assert result.path == path == campaign / "replay" / "case_1.html"
    assert result.status == "ok"
    assert [p.name for p in path.parent.iterdir()] == ["case_1.html"]  # no temp file left
    html = path.read_text()
    assert result.bytes == len(html.encode())
    assert html.lstrip().lower().startswith("<!doctype html") or "<html" in html[:200].lower()

    commands = _commands(html)
    objects = {c["path"] for c in commands if c.get("type") == "set_object"}
    for shape in ("/oos/RH1/RH1/box", "/oos/RH2/RH2/box", "/oos/SA1/root/box", "/oos/arm/L2/link"):
        assert shape in objects

    # frames: duration x frame rate (+1, both ends), the same in every animated body
    duration = BEFORE + AFTER
    expected = round(duration * LOG_RATE) + 1
    assert result.frames == expected
    assert (result.start, result.end) == (255.0 - BEFORE, 255.0 + AFTER)
    clips = _animation(html)
    assert "/oos/RH1/RH1" in clips and "/oos/arm/L6" in clips
    for clip in clips.values():
        assert clip["fps"] == pytest.approx(LOG_RATE)
        times = [key["time"] for key in _track(clip, ".quaternion")]
        assert times == list(range(expected))

    # the hub's animated attitude is the run's recorded attitude (campaign time series, written
    # by the runner), converted to a quaternion independently of Drake: R = Rz(yaw) Ry(p) Rx(r)
    from scipy.spatial.transform import Rotation

    recorded = pd.read_parquet(store.timeseries_file(campaign, run_id))
    rpy = recorded[["phi_x [rad]", "phi_y [rad]", "phi_z [rad]"]].to_numpy()
    assert len(rpy) == expected
    assert np.abs(rpy).max() > 1e-4  # the dispersed initial error makes the check meaningful
    expected_q = Rotation.from_euler("xyz", rpy).as_quat()  # x, y, z, w (three.js order)
    animated_q = np.array([key["value"] for key in _track(clips["/oos/RH1/RH1"], ".quaternion")])
    signs = np.sign(np.sum(expected_q * animated_q, axis=1))[:, None]
    np.testing.assert_allclose(animated_q * signs, expected_q, atol=1e-12)


def _pose(clip: dict, k: int) -> np.ndarray:
    """Homogeneous world pose of an animated path at frame ``k`` (three.js x, y, z, w)."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(_track(clip, ".quaternion")[k]["value"]).as_matrix()
    T[:3, 3] = _track(clip, ".position")[k]["value"]
    return T


def test_replay_shows_the_arm_tip_holding_the_target(campaign):
    """Composing the drawn shapes' offsets with the animated body poses gives a physical scene:
    at the capture the arm tip J7 is on the target's port D2 (the SM1 bushing closes the gap),
    while the hub port D1 is still far from the target's D3 (docking comes at 880 s)."""
    from oos_drake.campaign.replay import replay_case

    result = replay_case(campaign, 0)
    html = result.path.read_text()
    static = {
        c["path"]: np.array(c["matrix"]).reshape(4, 4).T  # column-major 4x4
        for c in _commands(html)
        if c.get("type") == "set_transform"
    }
    clips = _animation(html)
    gaps, far = [], []
    for k in range(result.frames):
        J7 = _pose(clips["/oos/arm/L6"], k) @ static["/oos/arm/L6/port_J7"]
        D2 = _pose(clips["/oos/RH2/RH2"], k) @ static["/oos/RH2/RH2/port_D2"]
        D1 = _pose(clips["/oos/RH1/RH1"], k) @ static["/oos/RH1/RH1/port_D1"]
        D3 = _pose(clips["/oos/RH2/RH2"], k) @ static["/oos/RH2/RH2/port_D3"]
        gaps.append(np.linalg.norm(J7[:3, 3] - D2[:3, 3]))
        far.append(np.linalg.norm(D1[:3, 3] - D3[:3, 3]))
    assert max(gaps) < 1e-3  # [m]
    assert max(gaps[-4:]) < 1e-5  # held by SM1 2 s after the capture
    assert min(far) > 0.3  # [m]


def test_playback_speed_scales_the_frame_rate_not_the_frames(campaign):
    from oos_drake.campaign.replay import replay_case

    result = replay_case(campaign, 0, speed=5.0)
    clips = _animation(result.path.read_text())
    clip = clips["/oos/RH2/RH2"]
    assert clip["fps"] == pytest.approx(5.0 * LOG_RATE)
    assert len(_track(clip, ".position")) == result.frames == round((BEFORE + AFTER) * LOG_RATE) + 1


def test_bad_case_or_directory_is_rejected_and_writes_nothing(campaign, tmp_path):
    from oos_drake.app.campaign import main
    from oos_drake.campaign.replay import replay_case, replay_path

    with pytest.raises(ValueError, match=r"--case 7: no such run"):
        replay_case(campaign, 7)
    assert not replay_path(campaign, 7).exists()
    with pytest.raises(ValueError, match="not a campaign directory"):
        replay_case(tmp_path, 0)
    assert not (tmp_path / "replay").exists()
    with pytest.raises(ValueError, match="speed"):
        replay_case(campaign, 0, speed=0.0)
    assert main(["campaign", "replay", str(campaign), "--case", "7"]) == 2
    assert not replay_path(campaign, 7).exists()


def test_campaign_without_a_3d_model_is_rejected(tmp_path):
    """The demo campaign's single-axis simulator has no bodies to draw."""
    from oos_drake.campaign.replay import replay_case, replay_path
    from oos_drake.campaign.runner import run_campaign

    demo = (CAMPAIGNS / "demo.toml").read_text()
    assert "n_runs = 200" in demo and "after = 130.0" in demo
    spec = tmp_path / "demo.toml"
    spec.write_text(
        demo.replace("n_runs = 200", "n_runs = 1").replace("after = 130.0", "after = 5.0")
    )
    run_campaign(spec, tmp_path / "demo", workers=1, progress=False)
    with pytest.raises(ValueError, match="flexible-attitude.*no 3D model"):
        replay_case(tmp_path / "demo", 0)
    assert not replay_path(tmp_path / "demo", 0).exists()


def test_default_speed_plays_within_a_minute():
    from oos_drake.multibody.replay import default_speed

    assert default_speed(6.0) == 1.0
    assert default_speed(60.0) == 1.0
    assert default_speed(61.0) == 2.0
    assert default_speed(1500.0) == 25.0  # the whole mission in one minute
    assert default_speed(1.0e5) == 100.0


def test_equivalent_box_has_the_body_inertia():
    from oos_drake.multibody.replay import equivalent_box

    a, b, c, m = 0.4, 1.2, 3.0, 7.0
    I = m / 12.0 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    R = Rotation_about_z(0.3)
    sides, axes = equivalent_box(m, R @ I @ R.T)
    np.testing.assert_allclose(np.sort(sides), [a, b, c], rtol=1e-12)
    assert np.linalg.det(axes) == pytest.approx(1.0)
    # the axes diagonalize the rotated inertia
    D = axes.T @ (R @ I @ R.T) @ axes
    np.testing.assert_allclose(D - np.diag(np.diag(D)), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="mass"):
        equivalent_box(0.0, I)


def test_camera_frames_every_shape_and_no_farther():
    """Every sphere is inside the view cone, and the bounding sphere touches the cone scaled
    by the framing: the camera is as close as the framing allows (an independent check of the
    geometry: angles from the camera, not the formula)."""
    from oos_drake.multibody.replay import CAMERA_FOV_DEG, CAMERA_FRAMING, frame_camera

    rng = np.random.default_rng(3)
    centres = rng.uniform(-2.0, 2.0, (7, 3)) + np.array([40.0, -5.0, 12.0])  # far from 0
    radii = rng.uniform(0.1, 1.0, 7)
    camera, target = frame_camera(centres, radii)
    np.testing.assert_allclose(target, 0.5 * (centres.min(0) + centres.max(0)), rtol=1e-12)
    axis = (target - camera) / np.linalg.norm(target - camera)
    half = np.radians(CAMERA_FOV_DEG) / 2
    # angular radius of each sphere's far edge from the view axis, seen from the camera
    offsets = centres - camera
    along = offsets @ axis
    across = np.linalg.norm(offsets - np.outer(along, axis), axis=1)
    distance = np.linalg.norm(offsets, axis=1)
    edge = np.arctan2(across, along) + np.arcsin(radii / distance)
    assert np.all(edge < half)
    # the bounding sphere about the target fills the cone shrunk by the framing
    bound = np.max(np.linalg.norm(centres - target, axis=1) + radii)
    np.testing.assert_allclose(
        np.arcsin(CAMERA_FRAMING * bound / np.linalg.norm(target - camera)), half, rtol=1e-12
    )


def Rotation_about_z(angle: float) -> np.ndarray:  # noqa: N802 - reads like the math
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_diverging_run_is_replayed_up_to_the_divergence(tmp_path):
    from oos_drake.campaign.replay import replay_case
    from oos_drake.campaign.runner import run_campaign

    spec = SPEC.replace(
        "log_rate = 2.0 }", "log_rate = 2.0, divergence_limit = 1.0e-4, check_interval = 1.0 }"
    ).replace(
        'phi0_x = { distribution = "normal", mean = 0.0, std = 2.0e-3 }',
        'phi0_x = { distribution = "fixed", value = 1.0e-3 }',
    )
    assert "divergence_limit" in spec and '"fixed"' in spec
    path = tmp_path / "diverging.toml"
    path.write_text(spec)
    directory = tmp_path / "campaign"
    run_campaign(path, directory, workers=1, progress=False)
    runs = pd.read_parquet(directory / "runs.parquet")
    assert (runs["status"] == "diverged").all()

    result = replay_case(directory, 0)
    assert result.status == "diverged" and "beyond" in result.error
    # the attitude error (1e-3 rad) exceeds the limit at the first check, 1 s into the window
    assert result.start == 255.0 - BEFORE
    assert result.end == pytest.approx(result.start + 1.0)
    assert result.frames == round((result.end - result.start) * LOG_RATE) + 1
    clips = _animation(result.path.read_text())
    assert len(_track(clips["/oos/RH1/RH1"], ".quaternion")) == result.frames
