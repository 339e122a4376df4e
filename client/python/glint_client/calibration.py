"""A part's calibration for the render workers, read from the files Glint's calibration
commands write: `glint calibrate bsdf` (material.json, format "glint-material/1") and
`glint calibrate response` (response.json, "glint-response/1")."""

from __future__ import annotations

import json
import math
import pathlib
from dataclasses import dataclass
from typing import Any

#: The principled BSDF's parameters, each in [0, 1] (`PrincipledMaterial`'s fields).
MATERIAL_PARAMS = (
    "base_color",
    "metallic",
    "roughness",
    "specular",
    "spec_tint",
    "anisotropic",
    "sheen",
    "sheen_tint",
    "clearcoat",
    "clearcoat_gloss",
)


class CalibrationFileError(ValueError):
    """A calibration file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class ResponseCurve:
    """A camera response (Debevec–Malik): g⁻¹ as (DN, ln X) pairs and g as intensity
    (DN / max DN) over a grid of ln X."""

    bit_depth: int
    max_dn: int
    inverse_dn: list[float]
    inverse_ln_exposure: list[float]
    forward_ln_exposure: list[float]
    forward_intensity: list[float]

    def to_proto(self, calibration_pb2: Any) -> Any:
        return calibration_pb2.ResponseCurve(
            bit_depth=self.bit_depth,
            max_dn=self.max_dn,
            inverse_dn=self.inverse_dn,
            inverse_ln_exposure=self.inverse_ln_exposure,
            forward_ln_exposure=self.forward_ln_exposure,
            forward_intensity=self.forward_intensity,
        )


@dataclass(frozen=True)
class PartCalibration:
    """What the render workers need of a part: its fitted principled `material`, the
    camera's `response` and the `radiometric_scale` (relative radiance-map units per
    W·sr⁻¹·m⁻²: the material file's median `per_view[].radiometric_scale`)."""

    material: dict[str, float]
    response: ResponseCurve
    radiometric_scale: float

    def material_proto(self, camera_pb2: Any) -> Any:
        return camera_pb2.PrincipledMaterial(**self.material)

    @staticmethod
    def from_files(material_path: str | pathlib.Path, response_path: str | pathlib.Path) -> PartCalibration:
        """Reads both files; raises OSError if unreadable, CalibrationFileError if malformed."""
        material_doc = _read_json(material_path)
        response_doc = _read_json(response_path)
        return PartCalibration(
            material=_material(material_doc, material_path),
            response=_response(response_doc, response_path),
            radiometric_scale=_radiometric_scale(material_doc, material_path),
        )


def _read_json(path: str | pathlib.Path) -> dict[str, Any]:
    text = pathlib.Path(path).read_text()
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise CalibrationFileError(f"{path}: not JSON ({e})") from None
    if not isinstance(doc, dict):
        raise CalibrationFileError(f"{path}: expected a JSON object")
    return doc


def _material(doc: dict[str, Any], path: str | pathlib.Path) -> dict[str, float]:
    params = doc.get("params")
    if not isinstance(params, dict):
        raise CalibrationFileError(f"{path}: no \"params\" object (a glint calibrate bsdf material file?)")
    out = {}
    for name in MATERIAL_PARAMS:
        value = params.get(name, 0.0)
        if not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
            raise CalibrationFileError(f"{path}: params.{name} is {value!r}; a number in [0, 1]")
        out[name] = float(value)
    return out


def _radiometric_scale(doc: dict[str, Any], path: str | pathlib.Path) -> float:
    per_view = doc.get("per_view")
    scales = sorted(
        v["radiometric_scale"]
        for v in (per_view if isinstance(per_view, list) else [])
        if isinstance(v, dict)
        and isinstance(v.get("radiometric_scale"), (int, float))
        and math.isfinite(v["radiometric_scale"])
        and v["radiometric_scale"] > 0
    )
    if not scales:
        raise CalibrationFileError(
            f"{path}: no per_view[].radiometric_scale; refit it with glint calibrate bsdf"
        )
    # The upper median, as Glint's MaterialFile::radiometric_scale takes it.
    return float(scales[len(scales) // 2])


def _numbers(doc: dict[str, Any], key: str, sub: str, path: str | pathlib.Path) -> list[float]:
    values = doc.get(key, {}).get(sub) if isinstance(doc.get(key), dict) else None
    if not (isinstance(values, list) and all(isinstance(v, (int, float)) for v in values)):
        raise CalibrationFileError(f"{path}: {key}.{sub} must be a list of numbers")
    return [float(v) for v in values]


def _response(doc: dict[str, Any], path: str | pathlib.Path) -> ResponseCurve:
    for key in ("bit_depth", "max_dn"):
        if not isinstance(doc.get(key), int):
            raise CalibrationFileError(f"{path}: {key} must be an integer (a glint calibrate response file?)")
    return ResponseCurve(
        bit_depth=doc["bit_depth"],
        max_dn=doc["max_dn"],
        inverse_dn=_numbers(doc, "inverse", "dn", path),
        inverse_ln_exposure=_numbers(doc, "inverse", "ln_exposure", path),
        forward_ln_exposure=_numbers(doc, "forward", "ln_exposure", path),
        forward_intensity=_numbers(doc, "forward", "intensity", path),
    )
