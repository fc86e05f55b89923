"""Meshcat recording of logged mission states: the drawing behind ``oos campaign replay``.

:func:`record` draws the mission's bodies and records one animation frame per logged plant state;
:func:`oos_drake.campaign.replay.replay_case` re-simulates a campaign run and writes the recording
as a self-contained HTML page.

The SDF models carry no visual geometry, so the replay draws simple shapes on the plant's bodies
(nothing is added to the plant, the simulated dynamics are the campaign's):

- hubs ``RH1``, ``RH2`` and each array's panel: the **equivalent-inertia box** of the body, i.e.
  the uniform box with the body's mass and central principal inertia, ``a_i = sqrt(6 (I_j + I_k -
  I_i) / m)``, oriented along the principal axes at the centre of mass (chaser hub 1.27 x 1.17
  x 1.05 m, target hub 0.86 x 0.75 x 0.63 m, arrays 2.11 x 1.00 m and 1.44 x 0.60 m plates, as
  the scenario data's comments state; thin sides are drawn at least 2 cm);
- arm links ``L0..L6``: cylinders (radius 5 cm) from each link's joint to the next joint (the
  wrist link to the arm tip J7);
- the docking frames ``D1``, ``D2``, ``D3`` and the arm tip ``J7``: small spheres.

Each body is a Meshcat path whose world pose is set at every logged sample of the run
(``time_in_recording``); the shapes hang below it at fixed offsets. The frames are the samples
of the simulation's state logger (``log_rate`` of the campaign's simulator options), so the
recording holds ``duration x log_rate + 1`` frames (inclusive ends) played at ``speed`` times
real time (default: the window within a minute, see :func:`default_speed`). The camera starts
framed on the spacecraft (:func:`frame_camera`: the centre of the drawn shapes at the first
frame, from far enough that every shape is in view and no farther); Meshcat's floor grid is laid
3 m below that centre as a reference for the hubs' drift. The arrays are drawn rigid: their
modal bodies are fictitious (the modal coordinates are in the campaign's time series).
"""

from __future__ import annotations

import numpy as np

__all__ = ["default_speed", "equivalent_box", "frame_camera", "record", "recording_html"]

#: Meshcat root path of the replay's objects.
ROOT = "/oos"
#: Radius of the arm-link cylinders [m].
LINK_RADIUS = 0.05
#: Radius of the docking-frame spheres [m].
PORT_RADIUS = 0.04
#: Direction from the spacecraft's centre to the initial camera (world frame, any length).
CAMERA_DIRECTION = (7.0, -9.0, 5.0)
#: Vertical field of view of Meshcat's default camera [deg].
CAMERA_FOV_DEG = 75.0
#: Room around the spacecraft in the initial view [-] (1: its bounding sphere touches the edges).
CAMERA_FRAMING = 1.15
#: Height of Meshcat's floor grid relative to that midpoint [m].
GRID_DEPTH = -3.0
#: Playback speeds tried by :func:`default_speed` [-].
SPEEDS = (1, 2, 5, 10, 25, 50, 100)
#: Longest default playback [s].
PLAYBACK_TARGET = 60.0
#: Thinnest side of a drawn box [m] (the arrays are thin plates).
MIN_SIDE = 0.02

_COLORS = {
    "RH1": (0.75, 0.75, 0.78, 1.0),
    "RH2": (0.85, 0.55, 0.2, 1.0),
    "SA1": (0.15, 0.25, 0.65, 1.0),
    "SA2": (0.15, 0.25, 0.65, 1.0),
    "SA3": (0.2, 0.45, 0.75, 1.0),
    "SA4": (0.2, 0.45, 0.75, 1.0),
    "arm": (0.9, 0.9, 0.92, 1.0),
    "port": (0.9, 0.1, 0.1, 1.0),
}


def equivalent_box(mass: float, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sides and axes of the uniform box with a body's mass and central inertia.

    Parameters
    ----------
    mass : float
        Body mass [kg].
    inertia : ndarray, shape (3, 3)
        Rotational inertia about the centre of mass [kg m^2].

    Returns
    -------
    sides : ndarray, shape (3,)
        Box sides along the principal axes [m] (``a_i = sqrt(6 (I_j + I_k - I_i) / m)``, at
        least :data:`MIN_SIDE`).
    axes : ndarray, shape (3, 3)
        Principal axes as columns (a proper rotation, body frame).
    """
    if not (mass > 0.0):
        raise ValueError(f"equivalent box: mass must be positive, got {mass!r} kg")
    moments, axes = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    total = moments.sum()
    squares = 6.0 * (total - 2.0 * moments) / mass
    return np.sqrt(np.maximum(squares, MIN_SIDE**2)), axes


def frame_camera(
    centres: np.ndarray,
    radii: np.ndarray,
    direction=CAMERA_DIRECTION,
    fov_deg: float = CAMERA_FOV_DEG,
    framing: float = CAMERA_FRAMING,
) -> tuple[np.ndarray, np.ndarray]:
    r"""Camera position and target that frame a set of spheres.

    The target is the centre of the spheres' bounding box; the camera looks at it from
    ``direction``, at the distance where the bounding sphere of all spheres (about the target)
    fills the narrower field of view divided by ``framing``:

    .. math::

        d = \frac{\text{framing}\; R}{\sin(\text{fov} / 2)},
        \qquad R = \max_i (\lVert c_i - t \rVert + r_i)

    Parameters
    ----------
    centres : ndarray, shape (n, 3)
        Centres of the shapes in the world frame [m].
    radii : ndarray, shape (n,)
        Radius of a sphere around each shape [m].
    direction : array_like, shape (3,)
        From the target towards the camera (world frame; normalized here).
    fov_deg : float
        Field of view [deg] (Meshcat's default camera: 75 deg vertically).
    framing : float
        Room around the spacecraft [-] (>= 1).

    Returns
    -------
    camera, target : ndarray, shape (3,)
        Camera position and the point it looks at, world frame [m].
    """
    centres = np.atleast_2d(np.asarray(centres, dtype=float))
    radii = np.asarray(radii, dtype=float).reshape(-1)
    target = 0.5 * (centres.min(axis=0) + centres.max(axis=0))
    radius = float(np.max(np.linalg.norm(centres - target, axis=1) + radii))
    unit = np.asarray(direction, dtype=float)
    unit = unit / np.linalg.norm(unit)
    distance = framing * radius / np.sin(np.radians(fov_deg) / 2.0)
    return target + distance * unit, target


def _shape_radius(shape) -> float:
    """Radius of a sphere around a drawn shape (box, cylinder, sphere) [m]."""
    from pydrake.geometry import Box, Cylinder, Sphere

    if isinstance(shape, Box):
        return 0.5 * float(np.linalg.norm([shape.width(), shape.depth(), shape.height()]))
    if isinstance(shape, Cylinder):
        return float(np.hypot(shape.radius(), 0.5 * shape.length()))
    if isinstance(shape, Sphere):
        return float(shape.radius())
    return 0.0


def _visuals(handles):
    """``[(path, body, shape, X_BS, rgba)]`` and ``{path: body}`` of the drawn bodies."""
    from pydrake.geometry import Box, Cylinder, Sphere
    from pydrake.math import RigidTransform, RotationMatrix

    from oos_drake.multibody.plant_parts import central_inertia

    plant = handles.plant
    shapes, bodies = [], {}

    def body_path(body):
        instance = plant.GetModelInstanceName(body.model_instance()).split("::")[-1]
        return f"{ROOT}/{instance}/{body.name()}", instance

    def add(body, name, shape, X_BS, rgba):
        path, _ = body_path(body)
        bodies[path] = body
        shapes.append((f"{path}/{name}", shape, X_BS, rgba))

    # hubs and array panels: equivalent-inertia boxes at the centre of mass
    hub_bodies = [handles.hub_joint.child_body(), handles.target_body]
    panels = [joint.child_body() for joint in handles.drive_joints]
    for body in hub_bodies + panels:
        mass, com, inertia = central_inertia(body.default_spatial_inertia())
        sides, axes = equivalent_box(mass, inertia)
        _, instance = body_path(body)
        add(
            body,
            "box",
            Box(*sides),
            RigidTransform(RotationMatrix(axes), com),
            _COLORS.get(instance, _COLORS["arm"]),
        )
    # arm links: a cylinder from each link's joint to the next joint (the wrist to J7)
    arm = list(handles.arm_joints)
    links = [arm[0].parent_body()] + [joint.child_body() for joint in arm]
    ends = [joint.frame_on_parent() for joint in arm] + [handles.frames["J7"]]
    for link, end in zip(links, ends, strict=True):
        p = end.GetFixedPoseInBodyFrame().translation() if end.body() is link else np.zeros(3)
        length = float(np.linalg.norm(p))
        if length < 1e-6:
            continue
        z = p / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        add(
            link,
            "link",
            Cylinder(LINK_RADIUS, length),
            RigidTransform(RotationMatrix(R), 0.5 * p),
            _COLORS["arm"],
        )
    for name in ("D1", "D2", "D3", "J7"):
        frame = handles.frames[name]
        add(
            frame.body(),
            f"port_{name}",
            Sphere(PORT_RADIUS),
            frame.GetFixedPoseInBodyFrame(),
            _COLORS["port"],
        )
    return shapes, bodies


def record(meshcat, handles, times: np.ndarray, states: np.ndarray, speed: float = 1.0) -> int:
    """Draw the scene and record one animation frame per logged state.

    Parameters
    ----------
    meshcat : pydrake.geometry.Meshcat
    handles : MissionDiagram
        The diagram the states belong to.
    times : ndarray, shape (n,)
        Sample times [s], uniformly spaced.
    states : ndarray, shape (nq + nv, n)
        Plant states at ``times``.
    speed : float
        Playback speed [-]: simulated seconds per animation second.

    Returns
    -------
    int
        Frames recorded (``n``).
    """
    from pydrake.geometry import Rgba
    from pydrake.math import RigidTransform

    plant = handles.plant
    nq = plant.num_positions()
    n = times.size
    rate = (n - 1) / (times[-1] - times[0]) if n > 1 else 1.0
    fps = rate * speed
    shapes, bodies = _visuals(handles)
    meshcat.Delete(ROOT)
    for path, shape, X_BS, rgba in shapes:
        meshcat.SetObject(path, shape, Rgba(*rgba))
        meshcat.SetTransform(path, X_BS)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, states[:nq, 0])
    # frame the camera on the shapes as drawn at the first frame
    centres = [
        (plant.EvalBodyPoseInWorld(context, bodies[path.rsplit("/", 1)[0]]) @ X_BS).translation()
        for path, _, X_BS, _ in shapes
    ]
    radii = [_shape_radius(shape) for _, shape, _, _ in shapes]
    camera, centre = frame_camera(np.array(centres), np.array(radii))
    meshcat.SetCameraPose(camera, centre)
    # the default floor grid would cut through the hub: lay it below the spacecraft
    meshcat.SetTransform("/Grid", RigidTransform(centre + np.array([0.0, 0.0, GRID_DEPTH])))
    meshcat.DeleteRecording()
    meshcat.StartRecording(frames_per_second=fps, set_visualizations_while_recording=False)
    for k in range(n):
        plant.SetPositions(context, states[:nq, k])
        index = round((times[k] - times[0]) * rate)
        # a quarter frame past the frame's start, so floor(time * fps) is the index exactly
        time_in_recording = (index + 0.25) / fps
        for path, body in bodies.items():
            meshcat.SetTransform(path, plant.EvalBodyPoseInWorld(context, body), time_in_recording)
    meshcat.StopRecording()
    return n


def recording_html(
    handles, times: np.ndarray, states: np.ndarray, speed: float = 1.0, *, meshcat=None
) -> tuple[str, int]:
    """:func:`record` the states and return the recording as a self-contained HTML page.

    Parameters
    ----------
    handles, times, states, speed
        As for :func:`record`.
    meshcat : pydrake.geometry.Meshcat, optional
        Visualizer to record into (default: a new one on a free local port, closed after).

    Returns
    -------
    html : str
        ``meshcat.StaticHtml()`` with the published recording.
    frames : int
        Frames recorded.
    """
    owned = meshcat is None
    if owned:
        from pydrake.geometry import Meshcat, MeshcatParams

        params = MeshcatParams()
        params.host = "localhost"
        meshcat = Meshcat(params)
    frames = record(meshcat, handles, times, states, speed)
    meshcat.PublishRecording()
    html = meshcat.StaticHtml()
    if owned:
        meshcat = None  # closes the server and its port
    return html, frames


def default_speed(duration: float) -> float:
    """Playback speed that shows ``duration`` [s] in at most :data:`PLAYBACK_TARGET` seconds.

    The smallest of :data:`SPEEDS` that does (the largest if none does): a 6 s window plays in
    real time, the 1500 s mission at 25x (one minute).
    """
    for speed in SPEEDS:
        if duration / speed <= PLAYBACK_TARGET + 1e-9:
            return float(speed)
    return float(SPEEDS[-1])
