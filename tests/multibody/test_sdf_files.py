"""The committed SDF files: generated from the scenario data, parsed by Drake, validated."""

import shutil

import numpy as np
import pytest

from oos_drake.multibody.scenario_sdf import (
    ASSEMBLY_FILE,
    SDF_DIRECTORY,
    generate_sdf_texts,
    same_sdf_text,
    stale_sdf_files,
    write_sdf,
)
from oos_drake.multibody.sdf_validation import SdfError, validate_sdf_tree
from oos_drake.scenario.data import load_scenario

SCENARIO = load_scenario()


def test_committed_sdf_is_up_to_date():
    stale = stale_sdf_files(SDF_DIRECTORY, SCENARIO)
    assert not stale, f"stale SDF files {stale}: run `oos sdf generate`"


def test_sdf_check_ignores_round_off_but_not_changes():
    # the last digits of generated values depend on the BLAS/LAPACK build (numpy 2.4 vs 2.3)
    ref = "<pose>2.418265431944897e-06 -3.0481731553550655 0 0 0 0</pose><mass>8.393</mass>"
    ulps = "<pose>2.4182654319448973e-06 -3.048173155355067 0 0 0 0</pose><mass>8.393</mass>"
    assert same_sdf_text(ulps, ref)
    assert not same_sdf_text(ulps.replace("8.393", "8.394"), ref)  # a changed mass
    assert not same_sdf_text(ulps.replace("-3.048173155355067", "-3.0481"), ref)
    assert not same_sdf_text(ulps.replace("<mass>", "<massx>"), ref)  # a changed tag
    assert not same_sdf_text(ref + "<link/>", ref)


def test_sdf_directory_holds_only_generated_files():
    generated = set(generate_sdf_texts(SCENARIO))
    present = {p.name for p in SDF_DIRECTORY.iterdir() if not p.name.startswith(".")}
    assert present == generated


def test_generation_is_deterministic_and_follows_the_data(tmp_path):
    assert generate_sdf_texts(SCENARIO) == generate_sdf_texts(SCENARIO)
    write_sdf(tmp_path, SCENARIO)
    assert stale_sdf_files(tmp_path, SCENARIO) == []
    text = (tmp_path / "hub_RH2.sdf").read_text()
    (tmp_path / "hub_RH2.sdf").write_text(text.replace("<mass>24.96</mass>", "<mass>25.0</mass>"))
    assert stale_sdf_files(tmp_path, SCENARIO) == ["hub_RH2.sdf"]


def _copy_tree(tmp_path):
    target = tmp_path / "sdf"
    shutil.copytree(SDF_DIRECTORY, target)
    return target


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            "<mass>24.96</mass>",
            "<mass>-24.96</mass>",
            r"hub_RH2\.sdf: link 'RH2': mass must be > 0",
        ),
        (
            "<ixx>2.684</ixx>",
            "<ixx>-2.684</ixx>",
            r"hub_RH2\.sdf: link 'RH2': inertia not positive definite",
        ),
        (
            "<izz>2.32</izz>",
            "<izz>9.0</izz>",
            r"hub_RH2\.sdf: link 'RH2': principal moments .* triangle",
        ),
    ],
)
def test_invalid_inertia_names_file_and_link(tmp_path, old, new, message):
    directory = _copy_tree(tmp_path)
    path = directory / "hub_RH2.sdf"
    assert old in path.read_text()
    path.write_text(path.read_text().replace(old, new))
    with pytest.raises(SdfError, match=message) as error:
        validate_sdf_tree(directory / ASSEMBLY_FILE)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    "frame, file_name", [("D2", "hub_RH2.sdf"), ("D1", "hub_RH1.sdf"), ("J7", "arm_ur5.sdf")]
)
def test_missing_port_frame_names_file_and_frame(tmp_path, frame, file_name):
    from oos_drake.multibody.scenario_plant import REQUIRED_FRAMES

    directory = _copy_tree(tmp_path)
    path = directory / file_name
    text = path.read_text()
    assert f'<frame name="{frame}"' in text
    path.write_text(text.replace(f'<frame name="{frame}"', '<frame name="renamed"'))
    with pytest.raises(SdfError, match=rf"{file_name}: port frame '{frame}' missing"):
        validate_sdf_tree(directory / ASSEMBLY_FILE, REQUIRED_FRAMES)


@pytest.mark.drake
def test_builder_refuses_bad_sdf_before_drake_parses_it(tmp_path):
    from oos_drake.multibody.scenario_plant import build_scenario_diagram

    directory = _copy_tree(tmp_path)
    path = directory / "arm_ur5.sdf"
    path.write_text(path.read_text().replace("<mass>8.393</mass>", "<mass>0</mass>"))
    with pytest.raises(ValueError, match=r"arm_ur5\.sdf: link 'L2': mass must be > 0"):
        build_scenario_diagram("hub", sdf_directory=directory)


@pytest.mark.drake
def test_parsed_plant_has_the_data_masses_and_array_inertias():
    """Drake's parse of sdf/ (plus modal residuals) carries the scenario's masses and D_P."""
    from pydrake.multibody.tree import BodyIndex

    from oos_drake.multibody.plant_parts import drake_spatial_inertia_to_matrix
    from oos_drake.multibody.scenario_plant import ARRAYS, build_scenario_diagram

    handles = build_scenario_diagram("free")
    plant = handles.plant
    context = plant.CreateDefaultContext()
    expected_mass = (
        sum(h.mass for h in SCENARIO.hubs.values())
        + SCENARIO.arm.total_mass
        + sum(m.model.mass for m in SCENARIO.arrays.values())
    )
    # mode bodies and modal residuals cancel: the parsed bodies sum to the data's masses
    total = sum(plant.get_body(BodyIndex(i)).default_mass() for i in range(1, plant.num_bodies()))
    np.testing.assert_allclose(total, expected_mass, rtol=1e-12)
    for array in ARRAYS:
        mount = SCENARIO.arrays[array]
        instance = plant.GetModelInstanceByName(f"oos_scenario::{array}")
        root = plant.GetBodyByName("root", instance)
        indices = plant.GetBodyIndices(instance)
        M = plant.CalcSpatialInertia(context, root.body_frame(), indices)
        np.testing.assert_allclose(
            drake_spatial_inertia_to_matrix(M), mount.model.rigid_spatial_inertia, atol=1e-9
        )


@pytest.mark.drake
def test_only_arm_and_drive_joints_are_actuated():
    """Mode hinges are structural (no actuator); arm and array drives can be driven in a sim."""
    from oos_drake.multibody.scenario_plant import build_scenario_diagram

    plant = build_scenario_diagram("hub").plant
    names = sorted(plant.get_joint_actuator(i).name() for i in plant.GetJointActuatorIndices())
    expected = sorted([f"alpha_{i}" for i in range(1, 7)] + [f"theta_SA{k}" for k in range(1, 5)])
    assert names == expected


def test_each_scenario_gets_its_own_twin(tmp_path):
    """``scenario_sdf_directory``: the package's files for the paper; files generated from the
    scenario otherwise (one folder per distinct twin, shared by equal copies of a scenario)."""
    import pickle
    from pathlib import Path

    from oos_drake.multibody.scenario_sdf import scenario_sdf_directory

    assert scenario_sdf_directory(SCENARIO) == (SDF_DIRECTORY, None)
    user = load_scenario(Path(__file__).parents[1] / "data" / "user_chaser.toml")
    directory, keeper = scenario_sdf_directory(user)
    assert keeper is not None and directory != SDF_DIRECTORY
    assert stale_sdf_files(directory, user) == []
    assert "hub_RH1.sdf" in stale_sdf_files(SDF_DIRECTORY, user)  # another chaser hub
    assert scenario_sdf_directory(pickle.loads(pickle.dumps(user)))[0] == directory
    heavier = load_scenario(user.source, {"hubs.RH1.mass": 300.0})
    assert scenario_sdf_directory(heavier)[0] not in (directory, SDF_DIRECTORY)
