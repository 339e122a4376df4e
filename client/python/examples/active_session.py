#!/usr/bin/env python3
"""An active pose-refinement session on a Glint deployment, step by step.

With `--part NAME` (default zigzag) it sets up the MOCK camera's bin of that built-in part,
takes a stand-in detector's initial pose (the mock's ground truth perturbed like a template
detector's error: EVALUATION ONLY, a real cell uses its own detector) and scores every step
against the truth. With `--mesh FILE --unit mm --initial-pose x,y,z,qw,qx,qy,qz` it registers
your own mesh instead, uses the camera as it is (no bin set-up, no ground truth) and starts from
your pose (object -> world, metres).

    python3 client/python/examples/active_session.py --target 127.0.0.1:50051 --part zigzag --max-views 3

A secured deployment: `--token-file FILE` (default $GLINT_TOKEN_FILE) sends its token on every
call, `--tls-ca FILE` connects over TLS trusting that CA, `--tls-cert FILE --tls-key FILE`
present a client certificate (mutual TLS).

Exit codes: 0 the session ended (threshold or budget), 1 a failed session or call, 2 bad
input (flags, files, or a request the servers reject as INVALID_ARGUMENT).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import sys
import time
from dataclasses import dataclass
from typing import Any, NoReturn, Optional

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from glint_client import (  # noqa: E402 (the package beside this script, uninstalled)
    BUILTIN_PARTS,
    GlintClient,
    GlintError,
    MeshPart,
    PartCalibration,
    Pose,
    PoseDeviation,
    Session,
    SessionState,
    Step,
    StubsError,
    Symmetry,
    ViewPolicy,
    builtin_symmetry,
    pose_deviation,
    stand_in_detector,
)
from glint_client.detector import InitialPoseNoise  # noqa: E402

EXIT_FAILED = 1
EXIT_USAGE = 2


class UsageError(Exception):
    """Bad input: printed as one line, exit code 2."""


class OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are one line (no usage block) and exit 2."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def parse_resolution(text: str) -> tuple[int, int]:
    """`WIDTHxHEIGHT` in pixels, e.g. 1280x1024."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts) or min(int(p) for p in parts) <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT in pixels, e.g. 1280x1024")
    return int(parts[0]), int(parts[1])


def parse_pose(text: str) -> Pose:
    """`x,y,z,qw,qx,qy,qz`: translation in metres and a unit quaternion (normalised here if
    within 1e-3 of unit norm, as a hand-typed one is)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 7 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r} is not x,y,z,qw,qx,qy,qz (7 finite numbers, metres)")
    norm = math.sqrt(sum(v * v for v in values[3:]))
    if abs(norm - 1.0) > 1e-3:
        raise argparse.ArgumentTypeError(f"the quaternion of {text!r} has norm {norm:.6f}, not 1")
    return Pose(tuple(values[:3]), tuple(values[3:])).normalized()


def positive_int(text: str) -> int:
    if not text.isdigit() or int(text) <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive integer")
    return int(text)


def seed(text: str) -> int:
    if not text.isdigit() or int(text) >= 2**64:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer from 0 to 2^64 - 1")
    return int(text)


def finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def arguments(argv: Optional[list[str]]) -> argparse.Namespace:
    p = OneLineParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--target", required=True, help="the orchestrator, HOST:PORT")
    p.add_argument("--camera", help="the camera (CameraService, MockCameraService), HOST:PORT; default --target")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--part", help=f"a built-in part in the mock bin: {', '.join(BUILTIN_PARTS)} (default zigzag)")
    source.add_argument("--mesh", type=pathlib.Path, help="your own mesh (PLY, OBJ, STL); needs --unit and --initial-pose")
    p.add_argument("--unit", choices=["mm", "m"], help="unit of the --mesh file's coordinates")
    p.add_argument("--initial-pose", type=parse_pose, help="x,y,z,qw,qx,qy,qz: the initial object -> world pose, metres")
    p.add_argument("--instances", type=positive_int, default=6, help="parts in the mock bin (default 6)")
    p.add_argument("--seed", type=seed, default=1, help="seed of the bin, the detector's error and the session (default 1)")
    p.add_argument("--resolution", type=parse_resolution, default=(1280, 1024), help="mock image size WxH px (default 1280x1024)")
    p.add_argument("--spp", type=positive_int, default=2, help="samples per pixel of the mock's renders (default 2)")
    p.add_argument("--candidates", type=positive_int, default=20, help="candidate views, the camera's own (default 20)")
    p.add_argument("--policy", choices=[v.value for v in ViewPolicy], default="nbv", help="how the next view is chosen (default nbv)")
    p.add_argument("--max-views", type=positive_int, default=4, help="views at most (default 4)")
    p.add_argument("--entropy-threshold-nats", type=finite_float, default=0.0, help="stop below this pose entropy (default 0: budget only)")
    p.add_argument("--material", type=pathlib.Path, help="the part's material.json (glint calibrate bsdf), with --response")
    p.add_argument("--response", type=pathlib.Path, help="the camera's response.json (glint calibrate response), with --material")
    p.add_argument("--json", type=pathlib.Path, help="write a machine-readable record of the session here")
    p.add_argument("--token-file", type=pathlib.Path, default=os.environ.get("GLINT_TOKEN_FILE") or None,
                   help="send the token in this file as `authorization: Bearer <token>` on every call "
                        "(default $GLINT_TOKEN_FILE)")
    p.add_argument("--tls-ca", type=pathlib.Path, help="connect over TLS, trusting this CA (PEM) for the servers' certificates")
    p.add_argument("--tls-cert", type=pathlib.Path, help="client certificate (PEM) for servers that require one; with --tls-key and --tls-ca")
    p.add_argument("--tls-key", type=pathlib.Path, help="the client certificate's private key (PEM)")
    args = p.parse_args(argv)
    if (args.tls_cert is None) != (args.tls_key is None):
        raise UsageError("--tls-cert and --tls-key go together")
    if args.tls_cert is not None and args.tls_ca is None:
        raise UsageError("--tls-cert needs --tls-ca (the CA of the servers' certificates): a client certificate needs TLS")
    if args.mesh is None:
        args.part = args.part or "zigzag"
        if args.part not in BUILTIN_PARTS:
            raise UsageError(f"--part: unknown part {args.part!r}; one of {', '.join(BUILTIN_PARTS)}")
    elif args.unit is None or args.initial_pose is None:
        raise UsageError("--mesh needs --unit mm|m and --initial-pose x,y,z,qw,qx,qy,qz (no mock bin, no detector)")
    if (args.material is None) != (args.response is None):
        raise UsageError("--material and --response go together")
    if args.candidates < 2:
        raise UsageError("--candidates: at least 2 views")
    return args


@dataclass
class Truth:
    """EVALUATION ONLY: the target instance's true pose and the part's declared symmetry,
    from the mock's ground truth."""

    t_w_o: Pose
    symmetry: Symmetry

    def deviation(self, t_w_o: Pose) -> PoseDeviation:
        # Minimised over the part's whole declared group (n-fold, dihedral, continuous about z).
        return pose_deviation(t_w_o, self.t_w_o, self.symmetry)


def nats_or_dash(h: Optional[float]) -> str:
    return "-" if h is None else f"{h:.2f}"


HEADER = (
    f"{'step':>4} {'view':>5} {'points':>7} {'total':>8} {'h_pred':>10} {'h':>10} {'err_mm':>8} "
    f"{'err_deg':>7} {'capture_s':>9} {'refine_s':>9} {'predict_s':>9}  refine"
)


def row(step: Step, deviation: Optional[PoseDeviation]) -> str:
    mm = "-" if deviation is None else f"{deviation.translation_mm:.2f}"
    deg = "-" if deviation is None else f"{deviation.rotation_deg:.2f}"
    return (
        f"{step.step:>4} {step.view:>5} {step.view_points:>7} {step.total_points:>8} "
        f"{nats_or_dash(step.predicted_entropy_nats):>10} {step.entropy_nats:>10.2f} {mm:>8} {deg:>7} "
        f"{step.capture_ms * 1e-3:>9.2f} {step.refine_ms * 1e-3:>9.2f} {step.predict_ms * 1e-3:>9.2f}  {step.refine_status}"
    )


def nearest_instance(gt: list[Pose], t_w_o: Pose) -> int:
    return min(range(len(gt)), key=lambda i: math.dist(gt[i].translation_m, t_w_o.translation_m))


def write_json_atomically(path: pathlib.Path, record: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")
    os.replace(tmp, path)


def run(args: argparse.Namespace) -> int:
    started = time.monotonic()
    try:
        calibration = PartCalibration.from_files(args.material, args.response) if args.material else None
        part = MeshPart.from_file(args.mesh, args.unit) if args.mesh else args.part
        client = GlintClient(args.target, args.camera, token_file=args.token_file,
                             tls_ca=args.tls_ca, tls_cert=args.tls_cert, tls_key=args.tls_key)
    except OSError as e:
        raise UsageError(f"{e.filename}: {e.strerror}") from None
    except ValueError as e:  # CalibrationFileError, SecurityConfigError, a mesh's suffix, a target's scheme
        raise UsageError(str(e)) from None
    truth: Optional[Truth] = None
    detector: Optional[dict[str, Any]] = None
    with client:
        if args.mesh:
            candidates = client.candidate_views(args.candidates)
            initial_t_w_o = args.initial_pose
            print(f"Mesh {args.mesh} ({args.unit}); initial pose from --initial-pose; no ground truth (errors '-').")
        else:
            width_px, height_px = args.resolution
            scene = client.set_up_mock_bin(args.part, args.instances, args.seed, width_px, height_px, args.spp)
            print(f"Mock bin: {scene.instances} x {scene.name} (mesh sha256 {scene.mesh_sha256_hex[:12]}...), "
                  f"{width_px}x{height_px} px, {args.spp} spp, seed {args.seed}.")
            candidates = client.candidate_views(args.candidates)
            # EVALUATION ONLY: the mock's truth places the stand-in detector's guess and scores.
            gt = client.ground_truth(visibility_from_t_w_c=candidates[0])
            symmetry = builtin_symmetry(args.part)
            if args.initial_pose is not None:
                initial_t_w_o = args.initial_pose
                target = nearest_instance(gt.t_w_o, initial_t_w_o)
                how = "from --initial-pose, scored against the nearest instance"
            else:
                visibility = [(v.visib_fract, v.px_count_all) for v in gt.visibility]
                guess = stand_in_detector(gt.t_w_o, visibility, candidates[0], symmetry, args.seed)
                initial_t_w_o, target = guess.initial_t_w_o, guess.target
                how = ("from a STAND-IN DETECTOR that reads the mock's ground truth (evaluation only): "
                       f"{InitialPoseNoise().describe()}")
            truth = Truth(gt.t_w_o[target], symmetry)
            d0 = truth.deviation(initial_t_w_o)
            visib = gt.visibility[target].visib_fract if gt.visibility else math.nan
            print(f"Initial pose {how}.")
            print(f"  target: instance {target + 1} of {len(gt.t_w_o)}, {100 * visib:.0f} % visible from view 0; "
                  f"{d0.translation_mm:.1f} mm / {d0.rotation_deg:.1f} deg off (symmetry {symmetry.spec}).")
            detector = {
                "stand_in": args.initial_pose is None,
                "target_instance": target + 1,
                "visib_fract": finite_or_none(visib),
                "error_mm": d0.translation_mm,
                "error_deg": d0.rotation_deg,
            }
        session_id = client.start_session(
            part,
            initial_t_w_o,
            candidates_t_w_c=candidates,
            policy=args.policy,
            max_views=args.max_views,
            entropy_threshold_nats=args.entropy_threshold_nats,
            seed=args.seed,
            calibration=calibration,
        )
        print(f"Session {session_id}, policy {args.policy}, {len(candidates)} candidates, at most {args.max_views} views.")
        print(HEADER)
        steps: list[tuple[Step, Optional[PoseDeviation]]] = []
        final: Optional[Session] = None
        for event in client.run_session(session_id):
            if isinstance(event, Step):
                deviation = truth.deviation(event.t_w_o) if truth else None
                print(row(event, deviation), flush=True)
                steps.append((event, deviation))
            else:
                final = event
    assert final is not None  # run_session raises unless it ends with the final session
    print(f"Session {final.session_id}: {final.state.name}, {len(final.steps)} views"
          + (f"; error: {final.error}" if final.error else "") + ".")
    if args.json:
        write_json_atomically(args.json, record(args, final, steps, initial_t_w_o, detector, truth, time.monotonic() - started))
        print(f"Wrote {args.json}.")
    return 0 if final.state in (SessionState.CONVERGED, SessionState.BUDGET_SPENT) else EXIT_FAILED


def finite_or_none(x: Optional[float]) -> Optional[float]:
    return x if x is not None and math.isfinite(x) else None


def record(
    args: argparse.Namespace,
    session: Session,
    steps: list[tuple[Step, Optional[PoseDeviation]]],
    initial_t_w_o: Pose,
    detector: Optional[dict[str, Any]],
    truth: Optional[Truth],
    wall_s: float,
) -> dict[str, Any]:
    """The session as JSON. Everything but `session_id` and `times` is deterministic for a
    deterministic deployment and the same flags (entropies in nats, null where none)."""
    return {
        "session_id": session.session_id,
        "state": session.state.name,
        "error": session.error,
        "part": session.part,
        "policy": args.policy,
        "max_views": args.max_views,
        "entropy_threshold_nats": args.entropy_threshold_nats,
        "seed": args.seed,
        "mock_bin": None if args.mesh else {
            "instances": args.instances,
            "width_px": args.resolution[0],
            "height_px": args.resolution[1],
            "samples_per_pixel": args.spp,
        },
        "candidates": len(session.candidates_t_w_c),
        "initial_t_w_o": initial_t_w_o.to_json(),
        "detector": detector,
        "steps": [
            {
                "step": s.step,
                "view": s.view,
                "view_points": s.view_points,
                "total_points": s.total_points,
                "entropy_nats": finite_or_none(s.entropy_nats),
                "predicted_entropy_nats": finite_or_none(s.predicted_entropy_nats),
                "candidate_entropies_nats": [finite_or_none(h) for h in s.candidate_entropies_nats],
                "next_view": s.next_view,
                "refine_status": s.refine_status,
                "t_w_o": s.t_w_o.to_json(),
                "error_mm": d.translation_mm if d else None,
                "error_deg": d.rotation_deg if d else None,
            }
            for s, d in steps
        ],
        "truth_t_w_o": truth.t_w_o.to_json() if truth else None,
        "times": {
            "wall_s": wall_s,
            "steps": [
                {"step": s.step, "capture_ms": s.capture_ms, "refine_ms": s.refine_ms,
                 "predict_ms": s.predict_ms, "plan_ms": s.plan_ms}
                for s, _ in steps
            ],
        },
    }


def main(argv: Optional[list[str]] = None) -> int:
    name = pathlib.Path(sys.argv[0]).name
    args: Optional[argparse.Namespace] = None
    try:
        args = arguments(argv)
        return run(args)
    except UsageError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:  # writing --json
        print(f"{name}: error: {e.filename}: {e.strerror}", file=sys.stderr)
        return EXIT_FAILED
    except GlintError as e:
        hint = ""
        if e.code_name == "UNAUTHENTICATED":
            token_file = args.token_file if args else None
            hint = (f" (the token in {token_file} was refused)" if token_file
                    else " (no token was sent: --token-file FILE or GLINT_TOKEN_FILE)")
        elif e.rpc == "StartSession" and e.code_name == "FAILED_PRECONDITION" and "calibration" in e.message:
            hint = " (pass --material FILE --response FILE, or use --policy random or max-distance)"
        print(f"{name}: error: {e}{hint}", file=sys.stderr)
        return EXIT_USAGE if e.code_name == "INVALID_ARGUMENT" else EXIT_FAILED
    except StubsError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print(f"{name}: interrupted (the session runs on in the orchestrator)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
