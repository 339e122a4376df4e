//! The session store's mesh blob (`TriMesh::from_canonical_bytes`): whatever it accepts
//! round-trips to the same bytes.
#![no_main]

use glint_geometry::TriMesh;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Some(mesh) = TriMesh::from_canonical_bytes(data) {
        assert_eq!(mesh.canonical_bytes(), data);
    }
});
