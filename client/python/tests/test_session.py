"""Active sessions from Python against `glint serve all`: a small mock bin (640x512 px, 1 spp,
4 Zigzags, 12 candidates, 3 views) run through the typed wrapper and through
`examples/active_session.py`, and bad input answered with the field's name."""

import json
import math
import subprocess
import sys

import pytest

from glint_client import (
    GlintClient,
    GlintError,
    Pose,
    SessionState,
    Step,
    ViewPolicy,
    builtin_symmetry,
    pose_deviation,
    stand_in_detector,
)

from conftest import CLIENT, glint_binary

EXAMPLE = CLIENT / "examples" / "active_session.py"
BIN = dict(part="zigzag", instances=4, seed=1, width_px=640, height_px=512, samples_per_pixel=1)
CANDIDATES = 12
MAX_VIEWS = 3
#: The example's flags for the same bin and session as `BIN` with the max-distance policy.
EXAMPLE_FLAGS = [
    "--part", "zigzag", "--instances", "4", "--seed", "1", "--resolution", "640x512", "--spp", "1",
    "--candidates", str(CANDIDATES), "--max-views", str(MAX_VIEWS),
]


@pytest.fixture(scope="module")
def client(glint_all):
    with GlintClient(glint_all.addr) as c:
        yield c


def run_on_mock_bin(client, policy):
    """Sets up `BIN`, asks the stand-in detector (evaluation only) and runs a session with
    `policy`; returns (steps, final session, truth of the target, detector's guess,
    candidates)."""
    scene = client.set_up_mock_bin(**BIN)
    assert scene.instances == BIN["instances"] and scene.name == "zigzag" and len(scene.mesh_sha256_hex) == 64
    candidates = client.candidate_views(CANDIDATES)
    assert len(candidates) == CANDIDATES
    truth = client.ground_truth(visibility_from_t_w_c=candidates[0])
    assert len(truth.t_w_o) == len(truth.visibility) == BIN["instances"]
    symmetry = builtin_symmetry("zigzag")
    guess = stand_in_detector(
        truth.t_w_o, [(v.visib_fract, v.px_count_all) for v in truth.visibility], candidates[0], symmetry, BIN["seed"]
    )
    session_id = client.start_session(
        "zigzag", guess.initial_t_w_o, candidates_t_w_c=candidates, policy=policy, max_views=MAX_VIEWS, seed=BIN["seed"]
    )
    events = list(client.run_session(session_id))
    steps, final = events[:-1], events[-1]
    assert all(isinstance(s, Step) for s in steps)
    return steps, final, truth.t_w_o[guess.target], guess, candidates


@pytest.fixture(scope="module")
def max_distance_run(client):
    return run_on_mock_bin(client, ViewPolicy.MAX_DISTANCE)


def assert_a_complete_session(steps, final, candidates, policy):
    assert [s.step for s in steps] == list(range(MAX_VIEWS))
    views = [s.view for s in steps]
    assert views[0] == 0 and len(set(views)) == MAX_VIEWS and all(0 <= v < CANDIDATES for v in views)
    assert [s.next_view for s in steps] == views[1:] + [None]
    assert final.state == SessionState.BUDGET_SPENT and final.state.is_final and final.error == ""
    assert final.steps == steps and final.policy == policy and final.part == "zigzag"
    assert final.max_views == MAX_VIEWS and len(final.candidates_t_w_c) == CANDIDATES
    entropies = [s.entropy_nats for s in steps]
    assert all(math.isfinite(h) for h in entropies)
    # Every view adds its Fisher information to the pose's (eq 18-19), so the entropy cannot
    # rise from step to step, and three views hold strictly more than one.
    assert all(b <= a for a, b in zip(entropies, entropies[1:])), entropies
    assert entropies[-1] < entropies[0], entropies
    # Every refinement re-selects each view's points at its current pose, so the total is not
    # the running sum of the steps' view_points; it holds this view's and at least one more.
    assert steps[0].total_points == steps[0].view_points
    for s, view in zip(steps, views):
        assert 0 < s.view_points < s.total_points or s.step == 0
        assert s.refine_status in ("converged", "max_iterations"), s.refine_status
        # The step reports the candidate it took (left camera -> world), to a float's rounding.
        assert math.dist(s.t_w_c.translation_m, candidates[view].translation_m) < 1e-9
        assert len(s.covariance_upper) == 21 and s.capture_ms > 0 and s.refine_ms > 0


def test_a_max_distance_session_through_the_wrapper(client, max_distance_run):
    steps, final, gt_t_w_o, guess, candidates = max_distance_run
    assert_a_complete_session(steps, final, candidates, ViewPolicy.MAX_DISTANCE)
    # Max-Distance predicts nothing: no planner's entropies on the wire.
    assert all(s.predicted_entropy_nats is None and s.candidate_entropies_nats == [] for s in steps)
    assert math.dist(final.initial_t_w_o.translation_m, guess.initial_t_w_o.translation_m) < 1e-12
    # The refined pose lands within the paper's 5 mm of the truth (the detector is within 30 mm).
    symmetry = builtin_symmetry("zigzag")
    assert pose_deviation(steps[-1].t_w_o, gt_t_w_o, symmetry).translation_m < 5e-3
    # The orchestrator keeps it: GetSession and ListSessions, and a re-run replays it.
    assert client.get_session(final.session_id) == final
    assert final.session_id in [s.session_id for s in client.list_sessions()]
    replay = list(client.run_session(final.session_id))
    assert replay[:-1] == steps and replay[-1].state == SessionState.BUDGET_SPENT


def test_an_nbv_session_takes_the_least_predicted_entropy(client):
    steps, final, _, _, candidates = run_on_mock_bin(client, "nbv")
    assert_a_complete_session(steps, final, candidates, ViewPolicy.NBV)
    assert steps[0].predicted_entropy_nats is None  # the detector's view, not predicted
    for before, after in zip(steps, steps[1:]):
        predicted = before.candidate_entropies_nats
        assert len(predicted) == CANDIDATES
        taken = {s.view for s in steps if s.step <= before.step}
        assert all(predicted[v] is None for v in taken)
        open_views = {v: h for v, h in enumerate(predicted) if v not in taken}
        assert all(h is not None and math.isfinite(h) for h in open_views.values())
        assert after.view == min(open_views, key=open_views.get)
        assert after.predicted_entropy_nats == open_views[after.view]
    assert steps[-1].candidate_entropies_nats == []


def test_the_example_writes_a_complete_deterministic_record(glint_all, max_distance_run, tmp_path):
    steps, final, gt_t_w_o, guess, _ = max_distance_run
    out = tmp_path / "session.json"
    run = subprocess.run(
        [sys.executable, str(EXAMPLE), "--target", glint_all.addr, *EXAMPLE_FLAGS, "--policy", "max-distance",
         "--json", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 0, run.stderr
    assert "STAND-IN DETECTOR" in run.stdout and "evaluation only" in run.stdout
    rows = [line for line in run.stdout.splitlines() if line.split()[:1] in (["0"], ["1"], ["2"])]
    assert len(rows) == MAX_VIEWS, run.stdout
    record = json.loads(out.read_text())
    assert record["state"] == "BUDGET_SPENT" and record["part"] == "zigzag" and record["policy"] == "max-distance"
    assert record["session_id"] != final.session_id and record["candidates"] == CANDIDATES
    assert record["detector"]["stand_in"] is True and record["detector"]["target_instance"] == guess.target + 1
    assert set(record["times"]) == {"wall_s", "steps"} and len(record["times"]["steps"]) == MAX_VIEWS
    # The same bin, seed and policy as the wrapper's run: the same detector guess, views and
    # entropies (the deployment is deterministic; rounding of a reordered sum is allowed).
    assert Pose.from_json(record["initial_t_w_o"]) == guess.initial_t_w_o
    assert [s["view"] for s in record["steps"]] == [s.view for s in steps]
    for mine, theirs in zip(record["steps"], steps):
        assert set(mine) == {
            "step", "view", "view_points", "total_points", "entropy_nats", "predicted_entropy_nats",
            "candidate_entropies_nats", "next_view", "refine_status", "t_w_o", "error_mm", "error_deg",
        }
        assert mine["entropy_nats"] == pytest.approx(theirs.entropy_nats, abs=1e-9)
        assert mine["predicted_entropy_nats"] is None and mine["candidate_entropies_nats"] == []
        d = pose_deviation(theirs.t_w_o, gt_t_w_o, builtin_symmetry("zigzag"))
        assert mine["error_mm"] == pytest.approx(d.translation_mm, abs=1e-6)
        assert mine["error_deg"] == pytest.approx(d.rotation_deg, abs=1e-6)


def test_the_example_runs_a_users_mesh_from_a_given_pose(glint_all, client, tmp_path):
    """`--mesh`: the part is the user's file (here the Zigzag exported as PLY in mm), the camera
    is used as it is (the bin `BIN` the earlier tests left), the initial pose is given."""
    mesh = tmp_path / "bracket.ply"
    subprocess.run([glint_binary(), "mesh", "export", "--part", "zigzag", "--out", str(mesh), "--unit", "mm"],
                   check=True, capture_output=True, timeout=60)
    client.set_up_mock_bin(**BIN)
    candidates = client.candidate_views(CANDIDATES)
    truth = client.ground_truth(visibility_from_t_w_c=candidates[0])
    target = max(range(len(truth.t_w_o)), key=lambda i: truth.visibility[i].px_count_visib)
    # 2 mm along world x off the truth of the most visible instance.
    start = Pose((0.002, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)) @ truth.t_w_o[target]
    pose_flag = ",".join(f"{v:.9f}" for v in (*start.translation_m, *start.rotation_wxyz))
    out = tmp_path / "mesh.json"
    run = subprocess.run(
        [sys.executable, str(EXAMPLE), "--target", glint_all.addr, "--mesh", str(mesh), "--unit", "mm",
         "--initial-pose", pose_flag, "--policy", "max-distance", "--candidates", str(CANDIDATES),
         "--max-views", "2", "--json", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 0, run.stderr
    record = json.loads(out.read_text())
    assert record["part"] == "bracket" and record["state"] == "BUDGET_SPENT" and record["mock_bin"] is None
    assert [s["error_mm"] for s in record["steps"]] == [None, None]
    refined = Pose.from_json(record["steps"][-1]["t_w_o"])
    assert pose_deviation(refined, truth.t_w_o[target], builtin_symmetry("zigzag")).translation_m < 5e-3


def test_a_bad_start_session_names_the_field(client):
    bad = Pose((math.nan, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(GlintError) as error:
        client.start_session("zigzag", bad, policy="max-distance", max_views=2)
    assert error.value.code_name == "INVALID_ARGUMENT" and error.value.rpc == "StartSession"
    assert error.value.message.startswith("initial_t_w_o.translation_m.x"), error.value.message
    with pytest.raises(GlintError) as error:
        client.start_session("spoon", Pose(), policy="random")
    assert error.value.code_name == "INVALID_ARGUMENT"
    assert error.value.message.startswith("part.builtin"), error.value.message
    with pytest.raises(GlintError) as error:
        client.get_session("s-no-such-session")
    assert error.value.code_name == "NOT_FOUND"


def test_a_created_session_can_be_cancelled(client):
    client.set_up_mock_bin(**BIN)
    session_id = client.start_session("zigzag", Pose((0.0, 0.0, 0.01)), policy="random", max_views=2, default_candidates=4)
    cancelled = client.cancel_session(session_id)
    assert cancelled.state == SessionState.CANCELLED and cancelled.steps == []
    # Running a finished session replays it: no steps, the final state.
    assert [e.state for e in client.run_session(session_id)] == [SessionState.CANCELLED]


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--resolution", "640by512"], "--resolution"),
        (["--part", "spoon"], "unknown part 'spoon'"),
        (["--mesh", "/nonexistent/part.ply", "--unit", "mm", "--initial-pose", "0,0,0,1,0,0,0"], "/nonexistent/part.ply"),
        (["--mesh", "part.ply"], "--mesh needs --unit"),
        (["--policy", "greedy"], "--policy"),
    ],
)
def test_the_example_rejects_bad_input_in_one_line(flags, message):
    run = subprocess.run(
        [sys.executable, str(EXAMPLE), "--target", "127.0.0.1:9", *flags], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 2, (run.stdout, run.stderr)
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert message in run.stderr


def test_the_example_reports_a_mesh_the_server_rejects(glint_all, tmp_path):
    junk = tmp_path / "junk.stl"
    junk.write_bytes(b"not a mesh")
    run = subprocess.run(
        [sys.executable, str(EXAMPLE), "--target", glint_all.addr, "--mesh", str(junk), "--unit", "mm",
         "--initial-pose", "0,0,0.01,1,0,0,0", "--policy", "random", "--candidates", "4"],
        capture_output=True, text=True, timeout=60,
    )
    assert run.returncode == 2, (run.stdout, run.stderr)
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert "StartSession: INVALID_ARGUMENT: part.mesh" in run.stderr
