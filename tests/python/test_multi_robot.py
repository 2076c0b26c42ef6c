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
    for name, robot in summary["robots"].items():
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
    assert summary["robots"]["turtlebot_2"]["waiting_time"] == coordination["turtlebot_2"]["waiting_time"]
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
    assert summary["volume_emitted"] == pytest.approx(NOZZLE_FLOW * PRINTING_TIME, rel=0.03)


def test_without_the_coordinator_the_arms_collide():
    summary, coordination, _ = run(False)
    assert coordination is None
    assert summary["robots"]["turtlebot_1"]["contacts_with_robots"] > 0
    assert summary["robots"]["turtlebot_2"]["contacts_with_robots"] > 0
    assert "waiting_time" not in summary["robots"]["turtlebot_2"]
