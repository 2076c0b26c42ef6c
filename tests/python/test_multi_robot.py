"""Several robots that share a print (scenes/multi_robot_shared.sdf): with the coordinator, no robot
touches another or the print, turtlebot_2 waits for turtlebot_1's arm, and the wall is whole; without
it (the same scene, switched off from Python) the two arms collide."""
import pathlib

import numpy as np
import pytest

import m3dp

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "multi_robot_shared.sdf"
WALL_START, WALL_END = 0.0, 1.1  # m along x: the three chunks' ends (y = 0)
NOZZLE_FLOW = np.pi * 0.008**2 / 4 * 0.05  # m³/s: 8 mm nozzle, 0.05 m/s exit speed
PRINTING_TIME = (0.4 + 0.4 + 0.3) / 0.05  # s of extrusion in all: the chunks' lengths at 0.05 m/s


def robots(summary):
    """summary.json's robots (a list) by name."""
    return {robot["name"]: robot for robot in summary["robots"]}


def run(coordinated):
    sim = m3dp.Simulation(SCENE, threads=2)
    if not coordinated:
        sim.set_coordination(False)
    sim.step_to(sim.end_time)
    positions = np.array(sim.positions)
    coordination = sim.coordination
    summary = sim.close()
    return summary, coordination, positions


@pytest.fixture(scope="module")
def coordinated():
    return run(True)


def test_coordinated_robots_touch_nothing(coordinated):
    summary, coordination, _ = coordinated
    assert summary["status"] == "completed"
    for robot in summary["robots"]:
        name = robot["name"]
        assert robot["contacts_with_robots"] == 0, name
        assert robot["contacts_with_printed_material"] == 0, name
        assert robot["contacts_with_other"] == 0, name
    # What the coordinator measured at its decisions: never closer than its clearances (30 mm to a
    # robot; 10 mm to the print), within the distance a decision period's motion can take.
    for name, report in coordination.items():
        assert report["least_robot_distance"] > 0.025, name
        assert report["least_print_distance"] > 0.008, name
        assert report["blocked"] == 0, name


def test_the_robot_of_lower_priority_waits(coordinated):
    summary, coordination, _ = coordinated
    # turtlebot_1 (first in <priority>) never yields; turtlebot_2, whose arm meets turtlebot_1's at
    # x = 0.4, waits and slows until turtlebot_1 has lifted its nozzle away.
    assert coordination["turtlebot_1"]["conflicts"] == 0
    assert coordination["turtlebot_1"]["waiting_time"] == 0
    assert coordination["turtlebot_2"]["conflicts"] > 0
    assert coordination["turtlebot_2"]["waiting_time"] > 0.3
    assert coordination["turtlebot_2"]["waiting_time"] + coordination["turtlebot_2"]["slowed_time"] > 2
    assert robots(summary)["turtlebot_2"]["coordination"]["waiting_time_s"] == coordination["turtlebot_2"]["waiting_time"]
    assert all(report["rate"] == 1 for report in coordination.values())  # all done: nothing holds anyone


def test_the_wall_is_complete(coordinated):
    summary, _, positions = coordinated
    # Every centimetre of the wall's line holds material: the waiting robot finished its chunk.
    on_wall = positions[(np.abs(positions[:, 1]) < 0.012) & (positions[:, 2] < 0.02)]
    edges = np.arange(WALL_START + 0.01, WALL_END - 0.01 + 1e-9, 0.01)
    counts, _ = np.histogram(on_wall[:, 0], bins=edges)
    assert counts.min() > 0, f"gaps at x = {edges[:-1][counts == 0]}"
    # The material laid is what the three chunks ask for: a stopped nozzle extrudes nothing, a slowed
    # one in proportion.
    assert summary["volume_m3"]["emitted"] == pytest.approx(NOZZLE_FLOW * PRINTING_TIME, rel=0.03)


def test_without_the_coordinator_the_arms_collide():
    summary, coordination, _ = run(False)
    assert coordination is None
    assert robots(summary)["turtlebot_1"]["contacts_with_robots"] > 0
    assert robots(summary)["turtlebot_2"]["contacts_with_robots"] > 0
    assert "coordination" not in robots(summary)["turtlebot_2"]


BLOCKED_SCENE = """<?xml version="1.0"?>
<sdf version="1.9">
  <world name="blocked">
    <model name="floor">
      <static>true</static>
      <link name="floor">
        <collision name="floor"><pose>0.3 0 -0.01 0 0 0</pose><geometry><box><size>1.6 1.2 0.02</size></box></geometry></collision>
      </link>
    </model>
    <include><uri>model://turtlebot3_manipulator</uri><name>driver</name><pose>0 0 0 0 0 0</pose></include>
    <include><uri>model://turtlebot3_manipulator</uri><name>bystander</name><pose>0 0.45 0 0 0 0</pose></include>
    <plugin name="m3dp" filename="m3dp">
      <solver>
        <particle_radius unit="mm">2</particle_radius>
        <max_time_step>0.004</max_time_step>
        <end_time>7</end_time>
        <bounds><min>-0.4 -0.4 -0.05</min><max>1.0 0.8 0.3</max></bounds>
      </solver>
      <material name="paste" preset="clay_paste"><rheology><max_viscosity>1e4</max_viscosity></rheology></material>
      <!-- Printed material on the floor, 3 cm high, across the driver's way. -->
      <fluid_block name="print" material="paste"><min>0.35 -0.05 0</min><max>0.45 0.05 0.03</max></fluid_block>
      <robot name="driver">
        <mobile_base>
          <left_wheel>wheel_left_joint</left_wheel>
          <right_wheel>wheel_right_joint</right_wheel>
          <wheel_radius unit="mm">33</wheel_radius>
          <wheel_separation unit="mm">287</wheel_separation>
          <path start_time="0.5" speed="0.1"><line extrude="false"><start>0 0 0</start><end>0.5 0 0</end></line></path>
        </mobile_base>
      </robot>
      <coordinator><priority>driver bystander</priority></coordinator>
    </plugin>
  </world>
</sdf>
"""


@pytest.mark.parametrize("coordinated", [True, False])
def test_a_robot_stops_short_of_the_print(coordinated):
    # The driver's base path runs through printed material. Coordinated, it stops short of it (its
    # body's front is 6.9 cm ahead of its reference point) and waits there: at least the print
    # clearance (1 cm) short, at most that plus the last rate's look-ahead (¼ of 0.1 m/s over the
    # 1.5 s horizon) and a cell of the boxes around the print (1 cm); without the coordinator it
    # drives on to its path's end, through the material.
    sim = m3dp.Simulation.from_string(BLOCKED_SCENE, str(ROOT / "scenes" / "blocked.sdf"), threads=2)
    sim.set_coordination(coordinated)
    sim.step_to(sim.end_time)
    front = sim.base_pose("driver")[0] + 0.069
    if coordinated:
        report = sim.coordination["driver"]
        assert report["least_print_distance"] > 0.008
        assert report["waiting_time"] > 1
        assert 0.35 - 0.01 - 0.0375 - 0.01 < front < 0.35 - 0.008, front
    else:
        assert sim.base_pose("driver")[0] > 0.49
    sim.close()
