#!/usr/bin/env python3
"""Writes the seed corpus of every fuzz target into fuzz/corpus/<target>/: small valid inputs
(a tetrahedron in each mesh format, Glint's JSON files, BOP and ROBI files, one valid message of
each RPC request) that the fuzzers mutate from. Each input starts with the byte its target uses
to pick the format or message.

    python3 fuzz/make_seeds.py [CAPTURE_DIR]

CAPTURE_DIR: a `glint capture --exposure-stack` folder to take the dataset files from (e.g. the
demo's glint-out/calibration/zigzag/scene); without it only the built-in seeds are written.
Needs the Python client's packages (client/python/requirements-test.txt) for the messages."""

import json
import pathlib
import struct
import sys

ROOT = pathlib.Path(__file__).resolve().parent
REPO = ROOT.parent
sys.path.insert(0, str(REPO / "client" / "python"))


def write(target: str, name: str, data: bytes) -> None:
    folder = ROOT / "corpus" / target
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(data)


# A tetrahedron, mm.
V = [(0, 0, 0), (10, 0, 0), (0, 10, 0), (0, 0, 10)]
F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def meshes() -> None:
    ply_ascii = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
    ply_ascii += "".join(f"{x} {y} {z}\n" for x, y, z in V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in F)
    header = ply_ascii.split("end_header\n")[0].replace("ascii", "binary_little_endian") + "end_header\n"
    body = b"".join(struct.pack("<3f", *v) for v in V) + b"".join(struct.pack("<B3i", 3, *f) for f in F)
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in F)
    stl = "solid t\n" + "".join(
        "facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {V[i][0]} {V[i][1]} {V[i][2]}\n" for i in f) + "endloop\nendfacet\n"
        for f in F) + "endsolid t\n"
    stl_bin = b"\0" * 80 + struct.pack("<I", len(F)) + b"".join(
        struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *V[i]) for i in f) + b"\0\0" for f in F)
    write("mesh_files", "ply_ascii", b"\x00" + ply_ascii.encode())
    write("mesh_files", "ply_binary", b"\x00" + header.encode() + body)
    write("mesh_files", "obj", b"\x01" + obj.encode())
    write("mesh_files", "stl_ascii", b"\x02" + stl.encode())
    write("mesh_files", "stl_binary", b"\x82" + stl_bin)
    canonical = struct.pack("<QQ", len(V), len(F)) + b"".join(struct.pack("<3f", *(c / 1e3 for c in v)) for v in V) \
        + b"".join(struct.pack("<3I", *f) for f in F)
    write("canonical_mesh", "tetrahedron", canonical)


def calibration_files() -> None:
    assets = REPO / "assets" / "calibration" / "zigzag"
    write("calibration_files", "response", b"\x00" + (assets / "response.json").read_bytes())
    material = json.loads((assets / "material.json").read_text())
    small = {k: material[k] for k in ("format", "params")}
    small["per_view"] = [{"radiometric_scale": v["radiometric_scale"]} for v in material["per_view"]]
    write("calibration_files", "material", b"\x01" + json.dumps(small).encode())


def dataset_files(capture: pathlib.Path | None) -> None:
    robi_poses = {"0": {"obj_id": 1, "R": [1, 0, 0, 0, 1, 0, 0, 0, 1], "t": [0, 0, 0]}}
    write("dataset_files", "robi_poses", b"\x08" + json.dumps(robi_poses).encode())
    yml = "%YAML:1.0\nwidth: 1280\nheight: 1024\nfx: 1083.1\nfy: 1083.1\ncx: 639.5\ncy: 511.5\ndepth_unit: 0.1\n"
    write("dataset_files", "robi_camera", b"\x09" + yml.encode())
    if capture is None:
        return
    scene = capture / "test" / "000001"

    def first_image(path: pathlib.Path) -> bytes:
        value = json.loads(path.read_text())
        return json.dumps({"0": value["0"]}).encode()

    files = [
        (0, "rig", (scene / "glint" / "rig.json").read_bytes()),
        (1, "stack", (scene / "glint" / "exposure_stack" / "000000" / "stack.json").read_bytes()),
        (2, "scene_camera", first_image(scene / "scene_camera.json")),
        (3, "scene_gt", first_image(scene / "scene_gt.json")),
        (4, "scene_gt_info", first_image(scene / "scene_gt_info.json")),
        (5, "models_info", (capture / "models" / "models_info.json").read_bytes()),
        (6, "camera", (capture / "camera.json").read_bytes()),
        (7, "reference_surface", (scene / "glint" / "reference_surface.json").read_bytes()),
    ]
    for pick, name, data in files:
        write("dataset_files", name, bytes([pick]) + data)


def messages() -> None:
    from glint_client import stubs

    s = stubs.load()
    cam, com, est, unc, orc, cal = (s.camera_pb2, s.common_pb2, s.estimation_pb2, s.uncertainty_pb2,
                                    s.orchestrator_pb2, s.calibration_pb2)

    def pose(z=0.5):
        return com.Pose(translation_m=com.Vector3(x=0.0, y=0.0, z=z), rotation=com.UnitQuaternion(w=0.0, x=1.0, y=0.0, z=0.0),
                        parent_frame="world", child_frame="camera")

    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in F)
    mesh = cam.MeshFile(data=obj.encode(), format="obj", unit=com.LENGTH_UNIT_MILLIMETRE, name="tetrahedron")
    material = cam.PrincipledMaterial(base_color=0.6, metallic=0.4, roughness=0.5, specular=0.5)
    response = json.loads((REPO / "assets" / "calibration" / "zigzag" / "response.json").read_text())
    curve = cal.ResponseCurve(bit_depth=response["bit_depth"], max_dn=response["max_dn"],
                              inverse_dn=response["inverse"]["dn"], inverse_ln_exposure=response["inverse"]["ln_exposure"],
                              forward_ln_exposure=response["forward"]["ln_exposure"][::8],
                              forward_intensity=response["forward"]["intensity"][::8])
    intrinsics = com.PinholeIntrinsics(width_px=320, height_px=256, fx_px=270.8, fy_px=270.8, cx_px=160, cy_px=128)
    rig = cam.GetRigResponse(stereo=com.StereoRig(intrinsics=intrinsics, baseline_m=0.1), projector=intrinsics, max_dn=255,
                             exposure_s=0.01, projector_intensity_w_per_sr=1.0, shots_per_capture=8, window_radius_px=1,
                             pattern_fill=0.5)
    noise = unc.SensorNoiseModel(variance_by_bin=[1.0, 2.0, 3.0], floor_variance=0.5)
    upper = [1.0 if i in (0, 6, 11, 15, 18, 20) else 0.0 for i in range(21)]
    seeds = [
        (0, "set_up_scene", cam.SetUpSceneRequest(part=cam.PartSpec(builtin="gear"), instances=3, seed=1, width_px=320, height_px=256)),
        (0, "set_up_scene_mesh", cam.SetUpSceneRequest(part=cam.PartSpec(mesh=mesh), instances=2, material=material)),
        (1, "list_views", cam.ListCandidateViewsRequest(count=20, distance_m=0.5, cap_half_angle_deg=35)),
        (2, "capture", cam.CaptureRequest(t_w_c=pose(), seed=3, noise_shots=True)),
        (3, "exposure_stack", cam.CaptureExposureStackRequest(t_w_c=pose(), exposures_s=[1e-3, 2e-3, 4e-3], seed=1)),
        (4, "fit_bsdf", cal.FitBsdfRequest(scene_dir="/nonexistent", response=curve, views=[0, 1], iterations=5, starts=[0.5])),
        (5, "response", curve),
        (6, "refine_header", est.RefineHeader(mesh=com.MeshRef(sha256_hex="0" * 64, unit=com.LENGTH_UNIT_METRE, name="t"),
                                              initial_t_w_o=pose(0.0), views=1, erode_px=1, window_radius_px=1)),
        (7, "refine_response", est.RefineResponse(t_w_o=pose(0.0), covariance=com.SymmetricMatrix6(upper=upper),
                                                  information=com.SymmetricMatrix6(upper=upper), entropy_nats=-40.0)),
        (8, "register_object", unc.RegisterObjectRequest(mesh=mesh, material=material, response=curve, rig=rig,
                                                         radiometric_scale=400.0, noise=noise, shots_per_capture=8, pattern_fill=0.5)),
        (9, "predict", unc.PredictCandidatesRequest(object_sha256_hex="0" * 64, t_w_o=pose(0.0), candidates_t_w_c=[pose(), pose(0.6)],
                                                    candidate_indices=[0, 1], seed=1)),
        (10, "rig", rig),
        (12, "plan_next_view", est.PlanNextViewRequest(collected=com.SymmetricMatrix6(upper=upper),
                                                       candidates=[com.SymmetricMatrix6(upper=upper)] * 3, taken=[1])),
        (13, "register_mesh", mesh),
        (11, "start_session", orc.StartSessionRequest(part=cam.PartSpec(builtin="zigzag"), initial_t_w_o=pose(0.0),
                                                      candidates_t_w_c=[pose(), pose(0.6)], max_views=2, seed=1,
                                                      material=material, response=curve, radiometric_scale=400.0)),
    ]
    for pick, name, message in seeds:
        write("rpc_requests", name, bytes([pick]) + message.SerializeToString())

    # Chunk streams: a 4x2 MONO8 image in two chunks.
    header = cal.ExposureStackHeader(arrays=[com.ArrayHeader(name="a", image=com.Image(width_px=4, height_px=2,
                                                                                        encoding=com.IMAGE_ENCODING_MONO8),
                                                             size_bytes=8)])
    head = header.SerializeToString()
    chunks = b""
    for offset in (0, 4):
        c = com.BytesChunk(array=0, offset=offset, data=bytes(range(offset, offset + 4))).SerializeToString()
        chunks += bytes([len(c)]) + c
    write("chunk_streams", "image_two_chunks", struct.pack("<H", len(head)) + head + chunks)


if __name__ == "__main__":
    meshes()
    calibration_files()
    dataset_files(pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else None)
    messages()
    for target in ("mesh_files", "canonical_mesh", "calibration_files", "dataset_files", "rpc_requests", "chunk_streams"):
        print(target, len(list((ROOT / "corpus" / target).iterdir())), "seeds")
