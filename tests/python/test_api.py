"""The Python API (import m3dp) on the demo scene: stepping, state as numpy arrays, commands to the
robot and the print head, cameras, outputs, errors, two simulations in one process, the GIL."""
import json
import os
import pathlib
import threading
import time

import numpy as np
import pytest

import m3dp

ROOT = pathlib.Path(__file__).resolve().parents[2]
DEMO = ROOT / "scenes" / "ur10_wall.sdf"


def demo_text(**replacements):
    text = DEMO.read_text()
    for old, new in replacements.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


@pytest.fixture(scope="module")
def printed():
    """The demo stepped to 3.2 s (the nozzle reaches the first corner at about 1.7 s, then prints)."""
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(3.2)
    return sim


def test_steps_and_time():
    sim = m3dp.Simulation(DEMO, threads=1)
    assert sim.time == 0 and sim.steps == 0
    sim.step()
    assert sim.steps == 1
    assert 0 < sim.time <= 0.004 + 1e-9  # the scene's max_time_step
    sim.step_to(0.05)
    assert sim.time >= 0.05 - 1e-9
    assert sim.end_time == pytest.approx(31)
    assert sim.robots == ["ur10"]
    assert sim.print_heads == ["nozzle"]
    assert sorted(sim.cameras) == ["overview", "wrist"]
    assert sim.material_names == ["mortar"]


def test_particles_are_read_only_arrays_of_the_step(printed):
    sim = printed
    n = sim.particle_count
    assert n > 400, "the nozzle has printed for 1.4 s (13 cm³, 27 mm³ a particle)"
    positions = sim.positions
    assert positions.shape == (n, 3) and positions.dtype == np.float32
    assert not positions.flags.writeable
    with pytest.raises(ValueError):
        positions[0, 0] = 1.0
    # Two reads in one step are the same array: one copy a step.
    assert sim.positions is positions
    assert sim.velocities.shape == (n, 3)
    assert sim.material.shape == (n,) and sim.material.dtype == np.uint16 and (sim.material == 0).all()
    assert len(np.unique(sim.ids)) == n
    # The printed bead lies on the floor, inside the wall's square (0.58..0.82 m, -0.12..0.12 m).
    assert positions[:, 2].min() > -0.002 and np.median(positions[:, 2]) < 0.02
    assert 0.55 < np.median(positions[:, 0]) < 0.85
    # Density measured where the particles are: near the mortar's rest density inside the bead.
    density = sim.density
    assert density.shape == (n,)
    assert 0.97 * 2100 < np.percentile(density, 90) < 1.05 * 2100  # printable_mortar: 2100 kg/m³ at rest
    age = sim.age
    assert (age >= 0).all() and age.max() <= sim.time
    np.testing.assert_allclose(age, sim.time - sim.birth_time, atol=1e-6)


def test_robot_state_and_nozzle(printed):
    sim = printed
    names = sim.joint_names("ur10")
    assert names[0] == "shoulder_pan_joint" and len(names) == 6
    assert sim.joint_positions("ur10").shape == (6,)
    assert sim.joint_velocities("ur10").shape == (6,)
    assert np.isfinite(sim.joint_efforts("ur10")).all()
    links = sim.link_poses("ur10")
    assert "tool0" in links and links["tool0"].shape == (7,)
    nozzle = sim.nozzle("nozzle")
    assert nozzle["extruding"]
    # The exit is 0.15 m out along the flange's z axis, and printing on the first layer (8 mm).
    tool0 = links["tool0"]
    assert np.linalg.norm(nozzle["pose"][:3] - tool0[:3]) == pytest.approx(0.15, abs=1e-3)
    assert nozzle["pose"][2] == pytest.approx(0.008, abs=0.004)
    assert nozzle["volume_rate"] == pytest.approx(np.pi / 4 * 0.012**2 * 0.085, rel=1e-3)
    bodies = sim.bodies
    assert "ur10/forearm_link" in bodies or any(name.startswith("ur10/") for name in bodies)


def test_cameras(printed):
    wrist = printed.camera("wrist")
    assert wrist["rgb"].shape == (240, 320, 3) and wrist["rgb"].dtype == np.uint8
    assert wrist["depth"].shape == (240, 320) and wrist["depth"].dtype == np.float32
    assert wrist["segmentation"].shape == (240, 320)
    legend = printed.camera_legend()
    seen = {legend[int(i)]["kind"] for i in np.unique(wrist["segmentation"])}
    assert "material" in seen, f"the wrist camera sees the fresh bead: {seen}"
    hit = np.isfinite(wrist["depth"])
    assert 0.02 < wrist["depth"][hit].min() < 0.3
    assert not wrist["rgb"].flags.writeable


def test_nozzle_target_moves_the_arm():
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(0.1)
    target = [0.72, 0.1, 0.12]
    sim.set_nozzle_target("ur10", target)
    assert sim.external_control("ur10")
    sim.step_to(1.3)
    pose = sim.nozzle("nozzle")["pose"]
    assert np.linalg.norm(pose[:3] - target) < 0.001, pose
    # Pointing down: the exit frame's −z is the material's direction.
    x, y, z, w = pose[3:]
    down = np.array([-(2 * (x * z + w * y)), -(2 * (y * z - w * x)), -(1 - 2 * (x * x + y * y))])
    assert down @ [0, 0, -1] > 0.999
    # Back to the scene's path: the nozzle heads for where the path is now (on its way to the first
    # corner, which it reaches at 1.76 s and starts to print).
    sim.set_external_control("ur10", False)
    sim.step_to(2.6)
    assert not sim.external_control("ur10")
    assert sim.nozzle("nozzle")["pose"][2] < 0.03


def test_joint_targets():
    sim = m3dp.Simulation(DEMO, threads=2)
    start = sim.joint_positions("ur10")
    targets = start + [0.3, 0, 0, 0, 0, 0]
    sim.set_joint_targets("ur10", targets)
    sim.step_to(1.0)
    np.testing.assert_allclose(sim.joint_positions("ur10"), targets, atol=2e-3)
    with pytest.raises(m3dp.Error, match="5 joint targets for 6 joints"):
        sim.set_joint_targets("ur10", [0, 0, 0, 0, 0])
    with pytest.raises(m3dp.Error, match="no robot 'ur5'"):
        sim.joint_positions("ur5")


def test_extrusion_commands():
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(2.0)
    before = sim.particle_count
    sim.set_extrusion("nozzle", extruding=False)
    sim.step_to(2.4)
    assert sim.particle_count == before, "no material while extrusion is off"
    assert not sim.nozzle("nozzle")["extruding"] and sim.nozzle("nozzle")["volume_rate"] == 0
    sim.set_extrusion("nozzle", extruding=True, flow_scale=1.0)
    sim.step_to(2.8)
    nominal = sim.particle_count - before
    sim.set_extrusion("nozzle", flow_scale=2.0)
    assert sim.nozzle("nozzle")["flow_scale"] == pytest.approx(2.0)
    start = sim.particle_count
    sim.step_to(3.2)
    doubled = sim.particle_count - start
    assert doubled == pytest.approx(2 * nominal, rel=0.15), (nominal, doubled)
    with pytest.raises(m3dp.Error, match="flow scale"):
        sim.set_extrusion("nozzle", flow_scale=float("nan"))


def test_record_writes_a_run_folder(tmp_path):
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(0.2)
    sim.record(tmp_path / "run", mcap=True)
    sim.step_to(0.5)
    summary = sim.close()
    assert summary["status"] == "completed"
    files = {path.name for path in (tmp_path / "run").iterdir()}
    assert {"particles.pvd", "world.pvd", "run.mcap", "summary.json", "timing.csv"} <= files, files
    on_disk = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert on_disk["status"] == "completed"
    with pytest.raises(m3dp.Error, match="closed"):
        sim.step()


def test_two_simulations_are_independent():
    alone = m3dp.Simulation(DEMO, threads=1)
    alone.step_to(2.2)
    first, second = m3dp.Simulation(DEMO, threads=1), m3dp.Simulation(DEMO, threads=1)
    second.set_extrusion("nozzle", extruding=False)
    while first.time < 2.2 - 1e-12:
        first.step()
        second.step()
    assert first.steps == alone.steps
    np.testing.assert_array_equal(first.positions, alone.positions)
    assert second.particle_count == 0 and first.particle_count > 0


def test_stepping_releases_the_gil():
    # The main thread keeps running while another steps: no gap in its loop as long as a step, let
    # alone the whole step_to (which a held GIL would make it).
    sim = m3dp.Simulation(DEMO, threads=1)
    worker = threading.Thread(target=sim.step_to, args=(3.0,))
    start = last = time.perf_counter()
    longest_gap = 0.0
    worker.start()
    while worker.is_alive():
        now = time.perf_counter()
        longest_gap, last = max(longest_gap, now - last), now
    worker.join()
    elapsed = last - start
    assert sim.time >= 3.0 - 1e-9
    assert elapsed > 0.2
    assert longest_gap < elapsed / 4, (longest_gap, elapsed)


def test_scene_errors_name_the_file_and_line(tmp_path):
    with pytest.raises(m3dp.InputError) as missing:
        m3dp.Simulation(tmp_path / "nowhere.sdf")
    assert "nowhere.sdf" in str(missing.value)
    text = demo_text(**{"<max_time_step>0.004</max_time_step>": "<max_time_step>fast</max_time_step>"})
    line = next(number for number, row in enumerate(text.splitlines(), 1) if "fast" in row)
    with pytest.raises(m3dp.InputError) as bad:
        m3dp.Simulation.from_string(text, name=str(DEMO))
    assert bad.value.line == line and bad.value.file == str(DEMO)
    assert f"{DEMO}:{line}" in str(bad.value)
    assert isinstance(bad.value, m3dp.Error) and isinstance(bad.value, RuntimeError)


def test_paths_given_while_printing(tmp_path):
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(2.0)  # printing the first side of the square since 1.76 s
    # Replace the square by a short line elsewhere: the head travels there (0.26 m at the line's
    # 0.1 m/s: until 4.6 s), then prints it (until 5.6 s).
    sim.set_path("nozzle", """<path speed="0.1">
      <line><start>0.75 0.1 0.008</start><end>0.65 0.1 0.008</end></line>
    </path>""")
    sim.step_to(4.0)
    assert not sim.nozzle("nozzle")["extruding"], "travelling"
    sim.step_to(6.0)
    pose = sim.nozzle("nozzle")["pose"]
    np.testing.assert_allclose(pose[:3], [0.65, 0.1, 0.008], atol=2e-3)
    assert not sim.nozzle("nozzle")["extruding"], "the line is done"
    on_line = (np.abs(sim.positions[:, 1] - 0.1) < 0.01) & (sim.positions[:, 0] > 0.64) & (sim.positions[:, 0] < 0.76)
    assert on_line.sum() > 100, "the new line was printed"
    count = sim.particle_count
    # Append waypoints from a file, after a 0.5 s pause.
    (tmp_path / "more.csv").write_text("x,y,z,speed,extrude\n0.65,0.05,0.008,0.1,1\n0.75,0.05,0.008,0.1,1\n")
    sim.set_path("nozzle", '<path start_time="0.5"><waypoints file="more.csv"/></path>', append=True,
                 name=tmp_path / "appended.xml")
    sim.step_to(6.45)
    assert sim.particle_count == count, "paused"
    sim.step_to(8.5)
    assert sim.particle_count > count + 100
    with pytest.raises(m3dp.InputError) as bad:
        sim.set_path("nozzle", "<path>\n<line><start>0 0</start></line></path>", name=tmp_path / "bad.xml")
    assert bad.value.file == str(tmp_path / "bad.xml") and bad.value.line == 2


def test_base_paths_given_while_driving():
    sim = m3dp.Simulation(ROOT / "scenes" / "turtlebot_print.sdf", threads=2)
    sim.step_to(0.5)  # its scene path starts at 1 s: it stands at (0, 0) facing +x
    start = sim.base_pose("turtlebot")
    np.testing.assert_allclose(start[:2], [0, 0], atol=1e-3)
    # Instead of the scene's quarter circle: 0.1 m straight ahead at 0.05 m/s, from now on.
    sim.set_base_path("turtlebot", '<path speed="0.05"><line extrude="false"><start>0 0 0</start><end>0.1 0 0</end></line></path>')
    sim.step_to(3.5)
    np.testing.assert_allclose(sim.base_pose("turtlebot")[:2], [0.1, 0.0], atol=0.01)
    with pytest.raises(m3dp.Error, match="no mobile base"):
        m3dp.Simulation(DEMO).set_base_path("ur10", '<path><line><start>0 0 0</start><end>1 0 0</end></line></path>')


def test_layers_of_the_wall():
    # The demo's square is 0.96 m a layer at 0.1 m/s: its second layer starts at about 11.4 s.
    sim = m3dp.Simulation(DEMO, threads=2)
    sim.step_to(12.5)
    layer = sim.layer
    assert layer.shape == (sim.particle_count,) and layer.dtype == np.int32
    assert set(np.unique(layer)) == {0, 1}
    z = sim.positions[:, 2]
    # The second layer lies on the first: its particles are higher on average by about a layer (8 mm).
    assert 0.004 < z[layer == 1].mean() - z[layer == 0].mean() < 0.012
    # And it was born after every particle of the first.
    assert sim.birth_time[layer == 1].min() > sim.birth_time[layer == 0].max()


TWO_HEADS = """<?xml version="1.0"?>
<sdf version="1.9"><world name="two_heads">
  <model name="floor"><static>true</static><link name="floor"><collision name="floor">
    <pose>0 0 -0.01 0 0 0</pose><geometry><box><size>0.3 0.3 0.02</size></box></geometry>
  </collision></link></model>
  <plugin name="m3dp" filename="m3dp">
    <solver><particle_radius unit="mm">1.5</particle_radius><end_time>7</end_time>
      <bounds><min>-0.15 -0.15 -0.05</min><max>0.15 0.15 0.1</max></bounds></solver>
    <material name="mortar" preset="printable_mortar"><rheology><max_viscosity>1e4</max_viscosity></rheology></material>
    <!-- a: two layers along y = 0, the second from about 1.1 s. -->
    <print_head name="a" material="mortar">
      <nozzle><inner_diameter unit="mm">8</inner_diameter><exit_speed>0.1</exit_speed></nozzle>
      <path speed="0.1">
        <line><start>-0.05 0 0.006</start><end>0.05 0 0.006</end></line>
        <line extrude="false"><start>0.05 0 0.006</start><end>0.05 0 0.012</end></line>
        <line><start>0.05 0 0.012</start><end>-0.05 0 0.012</end></line>
      </path>
    </print_head>
    <!-- b: one layer along y = 0.08 while a prints its second. -->
    <print_head name="b" material="mortar">
      <nozzle><inner_diameter unit="mm">8</inner_diameter><exit_speed>0.1</exit_speed></nozzle>
      <path start_time="1.2" speed="0.1">
        <line><start>-0.05 0.08 0.006</start><end>0.05 0.08 0.006</end></line>
      </path>
    </print_head>
  </plugin>
</world></sdf>"""


def test_each_particle_keeps_the_layer_of_its_own_heads_path():
    # Layers are counted on the path of the nozzle a particle left: b's one layer, printed while a
    # prints its second, is b's layer 0; a path given at run time counts its own layers.
    sim = m3dp.Simulation.from_string(TWO_HEADS, name="two_heads.sdf", threads=2)
    sim.step_to(2.4)
    y, z, layer = sim.positions[:, 1], sim.positions[:, 2], sim.layer
    assert not layer.flags.writeable
    of_a, of_b = y < 0.04, y > 0.04
    assert of_a.sum() > 100 and of_b.sum() > 100
    assert set(np.unique(layer[of_a])) == {0, 1}
    assert 0.004 < z[of_a & (layer == 1)].mean() - z[of_a & (layer == 0)].mean() < 0.009
    assert set(np.unique(layer[of_b])) == {0}, "b's material was printed in b's first layer"
    assert sim.birth_time[of_b].min() > sim.birth_time[of_a & (layer == 1)].min(), "while a printed its second"
    # b given two layers of its own at y = -0.08.
    sim.set_path("b", """<path speed="0.1">
      <line><start>-0.05 -0.08 0.006</start><end>0.05 -0.08 0.006</end></line>
      <line extrude="false"><start>0.05 -0.08 0.006</start><end>0.05 -0.08 0.012</end></line>
      <line><start>0.05 -0.08 0.012</start><end>-0.05 -0.08 0.012</end></line>
    </path>""")
    sim.step_to(6.6)  # 0.19 m of travel to its start, then 2 s of printing
    y, z, layer = sim.positions[:, 1], sim.positions[:, 2], sim.layer
    new = y < -0.04
    assert set(np.unique(layer[new])) == {0, 1}
    assert 0.004 < z[new & (layer == 1)].mean() - z[new & (layer == 0)].mean() < 0.009


def test_a_nozzle_with_a_bore_reports_its_pump(printed):
    """A nozzle with walls (scenes/ur10_wall_bore.sdf) reports the pump's push while it prints and
    keeps the flow commanded; the exit-plane inlet reports none."""
    sim = m3dp.Simulation(ROOT / "scenes" / "ur10_wall_bore.sdf", threads=2)
    sim.step_to(2.5)
    nozzle = sim.nozzle("nozzle")
    assert nozzle["extruding"]
    assert nozzle["extrusion_force"] > 0 and nozzle["extrusion_pressure"] > 0, nozzle
    assert printed.nozzle("nozzle")["extrusion_pressure"] == 0
    # The volume adds up: what was asked for left the exit, was lost while blocked, or is in the bore
    # beyond what primed it (issue 58: the priming was counted as emitted, 15 % over the commanded).
    # Within one disc of particles (π D²/4 · 2r, the layer due but not yet emitted) and a few % of the
    # bore's volume (its material compressed by the pump).
    volume = sim.volume_m3
    bore = np.pi / 4 * 0.012**2 * 0.024  # m³: the scene's 12 mm bore, 24 mm long
    disc = np.pi / 4 * 0.012**2 * 2 * sim.particle_radius
    assert volume["commanded"] > 3 * disc, volume
    assert 0.7 * bore < volume["primed"] <= bore, volume  # whole discs, from a spacing below the bore's top
    assert volume["in_bores"] == pytest.approx(volume["primed"], abs=disc), volume  # the bore stays full
    assert volume["laid"] == pytest.approx(volume["emitted"] - volume["in_bores"], rel=1e-12)
    balance = volume["laid"] + volume["lost_at_nozzles"] + volume["in_bores"] - volume["primed"]
    assert abs(volume["commanded"] - balance) < disc + 0.03 * bore, volume
    assert nozzle["volume_in_bore_m3"] == pytest.approx(volume["in_bores"], rel=1e-12)
    summary = sim.close()
    assert summary["status"] == "completed", summary
    assert summary["volume_m3"]["laid"] == pytest.approx(volume["laid"], rel=1e-12)
    assert summary["volume_m3"]["in_bores"] == pytest.approx(volume["in_bores"], rel=1e-12)
    assert summary["nozzles"][0]["volume_laid_m3"] == pytest.approx(volume["laid"], rel=1e-12)
