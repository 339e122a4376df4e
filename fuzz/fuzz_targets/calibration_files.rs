//! The calibration files Glint reads: the camera response (`glint calibrate response`) and the
//! fitted material (`glint calibrate bsdf`). The first byte picks the file.
#![no_main]

use std::path::Path;

use glint_calibration::material_file::MaterialFile;
use glint_calibration::response::ResponseTable;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(file) else {
        return;
    };
    let origin = Path::new("fuzz.json");
    if pick % 2 == 0 {
        if let Ok(table) = ResponseTable::parse(text, origin) {
            // A table that parses answers every query without panicking.
            for dn in [0, 1, table.max_dn / 2, table.max_dn] {
                let _ = table.ln_exposure(dn);
                let _ = table.weight(dn);
            }
            for ln_x in [-20.0, 0.0, 20.0, f64::NAN] {
                let _ = table.intensity(ln_x);
            }
        }
    } else if let Ok(material) = MaterialFile::parse(text, origin) {
        let _ = material.params();
        let _ = material.radiometric_scale();
    }
});
