//! Dataset formats: BOP and ROBI.
//!
//! Glint writes its mock captures in the [BOP] scene format (plus a few Glint files under
//! `glint/`), and reads real datasets in the BOP format (T-LESS, ITODD, XYZ-IBD, ...) and in
//! ROBI's own layout, so that every later stage runs on both.
//!
//! Inside Glint everything is metres and radians, poses are `t_a_b` (maps frame b → frame a)
//! and pixel `(u, v)` has its centre at `(u + 0.5, v + 0.5)`. The files speak millimetres,
//! row-major rotation matrices and OpenCV's pixel convention (centres at integers); the
//! conversions live in [`transforms`] and in the readers and writers, nowhere else.
//!
//! Every error names the file, and for JSON the key as a JSON pointer (`/7/cam_R_w2c`).
//!
//! [BOP]: https://github.com/thodan/bop_toolkit/blob/master/docs/bop_datasets_format.md

pub mod bop;
pub mod calibration_scene;
mod error;
pub mod exposure_stack;
mod image_files;
mod json;
pub mod reference_file;
pub mod rig_file;
pub mod robi;
pub mod transforms;

pub use error::DatasetError;
pub use exposure_stack::{ExposureStackFiles, write_exposure_stack};
pub use image_files::{PatternImage, StereoSide, depth_from_units, depth_to_units, write_png_u8};
