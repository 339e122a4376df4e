"""Glint's five built-in parts and their declared symmetries (README "The five parts"), and a
user's own mesh as a `PartSpec`."""

from __future__ import annotations

import pathlib
from dataclasses import dataclass
from typing import Any, Union

from .symmetry import Symmetry

#: Built-in part names as the servers spell them, with each part's declared symmetry group.
BUILTIN_SYMMETRIES: dict[str, Symmetry] = {
    "eye-bolt": Symmetry.cyclic("z", 2),
    "tube-fitting": Symmetry.cyclic("z", 6),
    "chrome-screw": Symmetry.continuous("z"),
    "gear": Symmetry.dihedral("z", 20, "x"),
    "zigzag": Symmetry.cyclic("z", 2),
}
BUILTIN_PARTS: tuple[str, ...] = tuple(BUILTIN_SYMMETRIES)

#: Mesh units as the `--unit` flag spells them → `LengthUnit` enum names.
MESH_UNITS = {"mm": "LENGTH_UNIT_MILLIMETRE", "m": "LENGTH_UNIT_METRE"}
MESH_FORMATS = ("ply", "obj", "stl")


def builtin_symmetry(name: str) -> Symmetry:
    """The declared symmetry of a built-in part; ValueError naming the choices otherwise."""
    try:
        return BUILTIN_SYMMETRIES[name]
    except KeyError:
        raise ValueError(f"unknown part {name!r}; one of {', '.join(BUILTIN_PARTS)}") from None


@dataclass(frozen=True)
class MeshPart:
    """A user's mesh sent inline (`MeshFile`): the file's bytes, its format (ply, obj, stl)
    and the unit of its vertex coordinates ("mm" or "m")."""

    data: bytes
    format: str
    unit: str
    name: str = ""

    def __post_init__(self) -> None:
        if self.format not in MESH_FORMATS:
            raise ValueError(f"mesh format {self.format!r}; one of {', '.join(MESH_FORMATS)}")
        if self.unit not in MESH_UNITS:
            raise ValueError(f"mesh unit {self.unit!r}; one of {', '.join(MESH_UNITS)}")

    @staticmethod
    def from_file(path: str | pathlib.Path, unit: str, name: str | None = None) -> MeshPart:
        """Reads a PLY/OBJ/STL file (format from its suffix). Raises OSError if unreadable,
        ValueError for an unknown suffix or unit."""
        p = pathlib.Path(path)
        fmt = p.suffix.lower().lstrip(".")
        if fmt not in MESH_FORMATS:
            raise ValueError(f"{p}: unknown mesh format {p.suffix!r}; .ply, .obj or .stl")
        return MeshPart(p.read_bytes(), fmt, unit, name if name is not None else p.stem)


#: A part: a built-in part's name or a user's mesh.
PartLike = Union[str, MeshPart]


def part_spec(part: PartLike, camera_pb2: Any, common_pb2: Any) -> Any:
    """A `glint.v1.PartSpec`. Built-in names are passed on as given: the servers reject an
    unknown one naming `part.builtin`."""
    if isinstance(part, MeshPart):
        unit = common_pb2.LengthUnit.Value(MESH_UNITS[part.unit])
        return camera_pb2.PartSpec(
            mesh=camera_pb2.MeshFile(data=part.data, format=part.format, unit=unit, name=part.name)
        )
    return camera_pb2.PartSpec(builtin=part)
