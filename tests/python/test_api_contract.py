"""What a controller relies on from the Python API (issue 43): failures are loud (scene warnings,
a blown-up run, a closed simulation, bad arguments), the summary is summary.json's, arrays kept
across a step do not change under their holder, and the volume balance is readable while it runs."""
import json
import pathlib
import warnings

import numpy as np
import pytest

import m3dp

ROOT = pathlib.Path(__file__).resolve().parents[2]
DEMO = ROOT / "scenes" / "ur10_wall.sdf"

# A water block with nothing under it: it falls out of the bounds.
FALLING = """<?xml version="1.0"?>
<sdf version="1.9">
  <world name="falling">
    {world}
    <plugin name="m3dp" filename="m3dp">
      <solver>
        <particle_radius>0.005</particle_radius>
        <end_time>1.0</end_time>
        <bounds><min>-0.1 -0.1 -0.05</min><max>0.2 0.2 0.2</max></bounds>
      </solver>
      <material name="water"><density>1000</density><viscosity>0.001</viscosity></material>
      <fluid_block name="water" material="water"><min>0 0 0</min><max>0.1 0.1 0.1</max></fluid_block>
    </plugin>
  </world>
</sdf>
"""


def test_scene_warnings_reach_python():
    text = FALLING.format(world="<gravty>0 0 -9.81</gravty>")
    with pytest.warns(m3dp.SceneWarning, match=r"falling\.sdf:4: unknown element <gravty> in <world>, ignored; did you mean <gravity>"):
        m3dp.Simulation.from_string(text, name="falling.sdf", threads=1)
    # warnings.simplefilter("error") makes them errors, as for any Python warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(m3dp.SceneWarning):
            m3dp.Simulation.from_string(text, name="falling.sdf", threads=1)
    assert issubclass(m3dp.SceneWarning, UserWarning)


def test_a_blow_up_fails_the_run_and_the_summary_says_so(tmp_path):
    sim = m3dp.Simulation.from_string(FALLING.format(world=""), name="falling.sdf", threads=1)
    start = sim.particle_count
    with pytest.raises(m3dp.SimulationError, match=r"% of the material, left the bounds"):
        sim.step_to(1.0)
    assert sim.time < 0.5 and sim.particle_count < start / 2
    # It does not go on as if nothing happened.
    with pytest.raises(m3dp.SimulationError, match="the run failed"):
        sim.step()
    summary = sim.close()
    assert summary["status"] == "failed" and "left the bounds" in summary["error"]
    assert summary["volume_m3"]["removed"] > 0.5 * summary["volume_m3"]["in_particles"]


def test_close_returns_summary_json_and_the_simulation_refuses_commands_after(tmp_path):
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(0.1)
    sim.record(tmp_path / "run")
    sim.step_to(0.2)
    summary = sim.close()
    on_disk = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary.keys() == on_disk.keys()
    assert summary["mass_emitted_kg"] == on_disk["mass_emitted_kg"] and summary["steps"] == on_disk["steps"]
    assert "mass_emitted" not in summary
    # A second close gives the same summary, not an empty one.
    assert sim.close() == summary
    for command in (lambda: sim.step(), lambda: sim.step_to(1.0), lambda: sim.record(tmp_path / "again"),
                    lambda: sim.set_extrusion("nozzle", extruding=True), lambda: sim.set_external_control("ur10"),
                    lambda: sim.set_joint_targets("ur10", [0] * 6), lambda: sim.set_nozzle_target("ur10", [0.7, 0, 0.1]),
                    lambda: sim.set_coordination(True), lambda: sim.set_path("nozzle", "<path><line/></path>")):
        with pytest.raises(m3dp.Error, match="the simulation is closed"):
            command()
    # What it was can still be read.
    assert sim.time >= 0.2 - 1e-9


@pytest.mark.parametrize("threads", [-1, -8])
def test_threads_must_be_zero_or_more(threads):
    with pytest.raises(m3dp.Error, match=r"threads = -\d+: expected 0 \(every core\)"):
        m3dp.Simulation(DEMO, threads=threads)


def test_arrays_kept_across_a_step_do_not_change():
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(2.2)
    positions, ids, velocities = sim.positions, sim.ids, sim.velocities
    kept = positions.copy(), ids.copy(), velocities.copy()
    sim.step_to(2.4)  # emission and the Z-order reordering change the state's arrays
    assert sim.particle_count > len(ids)
    np.testing.assert_array_equal(positions, kept[0])
    np.testing.assert_array_equal(ids, kept[1])
    np.testing.assert_array_equal(velocities, kept[2])
    # The new step's arrays are new ones, and the ids tell which row is which particle.
    now, now_ids = sim.positions, sim.ids
    assert now is not positions and not np.array_equal(now_ids[: len(ids)], ids)
    row = {particle: i for i, particle in enumerate(now_ids)}
    moved = np.linalg.norm(now[[row[particle] for particle in ids]] - positions, axis=1)
    assert np.median(moved) < 0.01, "a particle moves millimetres in 0.2 s, not across the wall"


def test_the_volume_balance_while_it_runs():
    sim = m3dp.Simulation(DEMO, threads=2)
    assert sim.particle_radius == pytest.approx(0.0015)
    assert sim.particle_volume == pytest.approx(0.003**3)
    sim.step_to(2.5)
    volume = sim.volume_m3
    assert volume["emitted"] == pytest.approx(sim.particle_count * sim.particle_volume, rel=1e-6)
    assert volume["commanded"] == pytest.approx(volume["emitted"], rel=0.05)
    assert volume["lost_at_nozzles"] == 0 and volume["removed"] == 0
    nozzle = sim.nozzle("nozzle")
    assert nozzle["volume_emitted_m3"] == pytest.approx(volume["emitted"])
    assert nozzle["volume_commanded_m3"] == pytest.approx(volume["commanded"])
    assert nozzle["blocked"] is False and nozzle["blocked_time_s"] == 0
    assert sim.close()["volume_m3"]["emitted"] == pytest.approx(volume["emitted"], rel=1e-6)


STRAND = ROOT / "scenes" / "strand.sdf"


def test_a_head_under_external_control_extrudes_only_when_told():
    # The demo's path starts extruding at about 1.76 s; under external control from 1.0 s the head
    # stays off through that time, and extrudes once told to.
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(1.0)
    here = sim.nozzle("nozzle")["pose"][:3]
    sim.set_nozzle_target("ur10", here + [0.02, 0, 0.01])
    sim.set_extrusion("nozzle", flow_scale=1.0)  # extruding=None: not a command to extrude
    sim.step_to(2.5)
    nozzle = sim.nozzle("nozzle")
    assert nozzle["control"] == "external" and not nozzle["extruding"]
    assert sim.particle_count == 0, "no material on the abandoned path's clock"
    sim.set_extrusion("nozzle", extruding=True)
    sim.step_to(2.7)
    assert sim.nozzle("nozzle")["extruding"] and sim.particle_count > 0
    # Back to the path (5 cm away and more): it travels there without extruding, then prints.
    sim.set_extrusion("nozzle", extruding=None)
    sim.set_external_control("ur10", False)
    count, controls = sim.particle_count, []
    while sim.time < 3.6:
        sim.step()
        nozzle = sim.nozzle("nozzle")
        controls.append(nozzle["control"])
        if nozzle["control"] == "rejoining":
            assert not nozzle["extruding"] and sim.particle_count == count
    assert controls[0] == "rejoining" and controls[-1] == "path"
    assert sim.nozzle("nozzle")["extruding"] and sim.particle_count > count


def test_nozzle_targets_move_within_limits_and_unreachable_ones_are_refused():
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(1.0)
    start = sim.nozzle("nozzle")["pose"][:3].copy()
    goal = start + [0, 0, 0.032]
    sim.set_nozzle_target("ur10", goal, max_speed=0.1, max_acceleration=1.0)
    times, heights = [], []
    while sim.time < 1.8:
        sim.step()
        times.append(sim.time)
        heights.append(sim.nozzle("nozzle")["pose"][2])
    times, heights = np.array(times), np.array(heights)
    # A 32 mm move at 0.1 m/s and 1 m/s² takes 0.42 s: not there within 0.2 s, there after 0.6 s,
    # without overshooting or ringing.
    assert heights[times < 1.2].max() < goal[2] - 0.005
    settled = heights[times > 1.6]
    assert np.abs(settled - goal[2]).max() < 0.0015
    assert heights.max() < goal[2] + 0.0015
    speeds = np.abs(np.diff(heights) / np.diff(times))
    assert np.percentile(speeds, 95) < 0.13
    nozzle = sim.nozzle("nozzle")
    assert nozzle["arrived"] and np.allclose(nozzle["target"], goal)
    with pytest.raises(m3dp.Error, match=r"out of reach of robot 'ur10'"):
        sim.set_nozzle_target("ur10", [5.0, 0, 0.1])
    with pytest.raises(m3dp.Error, match="max_speed"):
        sim.set_nozzle_target("ur10", goal, max_speed=0)


def test_a_gantry_head_takes_targets_too():
    sim = m3dp.Simulation(STRAND, threads=2)
    sim.step_to(0.2)
    start = sim.nozzle("even")["pose"][:3].copy()
    goal = start + [0, 0.01, 0.02]
    sim.set_head_target("even", goal, max_speed=0.05, max_acceleration=0.5)
    assert sim.nozzle("even")["control"] == "external"
    sim.step_to(0.3)
    halfway = sim.nozzle("even")["pose"][:3]
    assert 0.001 < np.linalg.norm(halfway - start) < np.linalg.norm(goal - start) - 0.001
    sim.step_to(1.0)
    assert np.allclose(sim.nozzle("even")["pose"][:3], goal, atol=1e-6)
    assert not sim.nozzle("even")["extruding"]
    with pytest.raises(m3dp.Error, match="outside the scene's <bounds>"):
        sim.set_head_target("even", [2.0, 0, 0.01])
    # Released, it travels back to where its path is now, then follows it.
    sim.set_external_control("even", False)
    sim.step()
    assert sim.nozzle("even")["control"] == "rejoining"
    sim.step_to(1.6)
    assert sim.nozzle("even")["control"] == "path"
    with pytest.raises(m3dp.Error, match="no print head 'nowhere'"):
        sim.set_head_target("nowhere", goal)


def quaternion_matrix(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_camera_intrinsics_frames_and_points_on_request():
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(2.5)
    info = sim.camera_info("wrist")
    assert (info["width"], info["height"]) == (320, 240) and info["robot"] == "ur10"
    K = info["K"]
    assert K.shape == (3, 3) and K[0, 2] == pytest.approx(160) and K[1, 2] == pytest.approx(120)
    assert K[0, 0] == pytest.approx(160 / np.tan(info["horizontal_fov"] / 2))
    assert 0 < info["near"] < info["far"]
    # The SDF camera frame looks along its x axis; the optical frame along its z axis, the same way.
    camera, optical = quaternion_matrix(info["pose"][3:]), quaternion_matrix(info["optical_pose"][3:])
    np.testing.assert_allclose(camera[:, 0], optical[:, 2], atol=1e-6)
    np.testing.assert_allclose(camera[:, 1], -optical[:, 0], atol=1e-6)
    # The scene asks the wrist camera for no point cloud; on request it gives one in either frame.
    image = sim.camera("wrist")
    assert image["points"].shape == (0, 3) and image["points_frame"] == "none"
    in_optical = sim.camera("wrist", points="optical")
    in_world = sim.camera("wrist", points="world")
    depth = in_optical["depth"]
    rows, columns = np.nonzero(np.isfinite(depth))
    points = in_optical["points"]
    assert len(points) == len(rows) > 1000
    # Each optical point projects through K onto its pixel's centre, at its depth.
    projected = (K @ points.T).T
    np.testing.assert_allclose(projected[:, 0] / projected[:, 2], columns + 0.5, atol=0.01)
    np.testing.assert_allclose(projected[:, 1] / projected[:, 2], rows + 0.5, atol=0.01)
    np.testing.assert_allclose(points[:, 2], depth[rows, columns], rtol=1e-5)
    # And optical_pose takes them to the world's.
    world = (optical @ points.T).T + in_optical["optical_pose"][:3]
    np.testing.assert_allclose(world, in_world["points"], atol=1e-4)
    with pytest.raises(m3dp.Error, match="points='sideways'"):
        sim.camera("wrist", points="sideways")
    with pytest.raises(m3dp.Error, match=r"no camera 'nowhere' in the scene \(cameras: "):
        sim.camera_info("nowhere")


def test_the_print_joins_the_world_whether_or_not_it_is_recorded(tmp_path):
    # The demo meshes every 4 s: at 4.0 s its printed wall becomes the world's collision body, the
    # same for a simulation that records nothing and one that records from 1 s on.
    quiet, recorded = m3dp.Simulation(DEMO, threads=2), m3dp.Simulation(DEMO, threads=2)
    assert quiet.printed_mesh is None
    recorded.step_to(1.0)
    recorded.record(tmp_path / "run")
    for sim in (quiet, recorded):
        sim.step_to(4.2)
    mesh, mesh_recorded = quiet.printed_mesh, recorded.printed_mesh
    assert mesh is not None and mesh["meshes_made"] == 1 and len(mesh["triangles"]) > 1000
    # On the printed wall's square (0.58..0.82 m, −0.12..0.12 m), up to its first layers.
    assert 0.5 < mesh["vertices"][:, 0].mean() < 0.9 and mesh["vertices"][:, 2].max() < 0.05
    np.testing.assert_array_equal(mesh["vertices"], mesh_recorded["vertices"])
    np.testing.assert_array_equal(quiet.positions, recorded.positions)
    summary = recorded.close()
    assert summary["meshes_inserted"] == 1 and len(summary["meshes"]) == 2  # at 4 s, and the final state's
    assert (tmp_path / "run" / summary["meshes"][0]["file"]).exists()


def test_quality_of_the_print_so_far():
    # The demo's first side, printed by 4 s, against the path: the same figures as m3dp quality.
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(4.0)
    report = sim.quality(spacing=0.01)
    head = report["heads"][0]
    assert head["name"] == "nozzle"
    layer = head["layers"][0]
    assert layer["design_width_m"] == pytest.approx(0.01373, abs=1e-4)
    arrays = head["section_arrays"]
    printed = arrays["particles"] > 0
    assert 10 <= printed.sum() <= 30 and len(arrays["width_m"]) == head["sections"]
    assert layer["width_m"] == pytest.approx(arrays["width_m"][printed & (arrays["layer"] == 0)].mean())
    # Sections with material lie on the first side (y = -0.12 m, x from 0.58 m on).
    np.testing.assert_allclose(arrays["at_m"][printed][:, 1], -0.12, atol=1e-6)
    # The material still falling from the nozzle and the strand's ends lie in no cell half full: the
    # printed fill is 0.90 of the particles' volume (0.899-0.900 with the generic, AVX2 and AVX-512 sums).
    assert report["fill_m3"]["printed"] == pytest.approx(sim.particle_count * sim.particle_volume, rel=0.15)
    with pytest.raises(m3dp.Error, match="spacing"):
        sim.quality(spacing=0)
