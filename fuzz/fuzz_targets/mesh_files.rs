//! The PLY, OBJ and STL readers (`glint mesh`, `RegisterObject`'s and `Refine`'s mesh files,
//! BOP models): the first byte picks the format, the rest is the file.
#![no_main]

use glint_geometry::io::{MeshFormat, read_mesh_from_bytes};
use glint_geometry::mesh::LengthUnit;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let format = [MeshFormat::Ply, MeshFormat::Obj, MeshFormat::Stl][pick as usize % 3];
    let unit = if pick & 0x80 == 0 {
        LengthUnit::Millimetre
    } else {
        LengthUnit::Metre
    };
    if let Ok(loaded) = read_mesh_from_bytes(file, format, unit, "fuzz") {
        // Whatever reads must be a mesh the rest of Glint can use.
        assert!(loaded.mesh.vertices.iter().all(|v| v.coords.iter().all(|x| x.is_finite())));
    }
});
