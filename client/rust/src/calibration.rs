//! The calibration stage run through its service, as a cell runs it once before its sessions:
//! a calibration capture of the part in a bin of known poses (the mock camera records it to
//! disk, as `glint capture --exposure-stack` does), the camera response solved by
//! `CalibrationService.CalibrateResponse` from one of its exposure stacks (streamed in
//! chunks), the part's principled BSDF fitted by `CalibrationService.FitBsdf` on the capture.
//! The results are the files `glint calibrate response` and `glint calibrate bsdf` write, kept
//! in a cache folder the next run reads instead of calibrating again.
//!
//! `FitBsdf` reads the capture from the calibration server's disk: the server and this client
//! share a file system (the demo's in-process servers do).

use std::path::{Path, PathBuf};

use anyhow::Context;
use glint_calibration::material_file::MaterialFile;
use glint_calibration::response::DebevecConfig;
use glint_calibration::server::{response_from_message, response_to_message};
use glint_calibration::shipped::Calibration;
use glint_camera::dataset::ExposureStackFiles;
use glint_camera::dataset::bop::BopSceneLayout;
use glint_camera::materials;
use glint_camera::setup::{BinSetup, BinSetupSpec};
use glint_eval::capture_folder::record_exposure_stacks;
use glint_geometry::Part;
use glint_geometry::image::Image;
use glint_proto::chunks::{OutgoingArray, chunks};
use glint_proto::v1;
use glint_proto::v1::calibration_service_client::CalibrationServiceClient;

use crate::{ClientSecurity, channel, status};

/// Exposure times of the calibration stacks, seconds: 0.0625 ms to 64 ms in octaves, from
/// under-exposed on the matte Zigzag to over a third saturated on the shiny parts (the
/// default sensor's own Δt is 10 ms).
pub const CALIBRATION_EXPOSURES_S: [f64; 11] = [
    0.0625e-3, 0.125e-3, 0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3, 8e-3, 16e-3, 32e-3, 64e-3,
];

/// The calibration bin: its own seed (apart from every session's bins), 8 parts, 2 views —
/// the response is solved on the first view's stack, the material fitted on both.
pub const CALIBRATION_SEED: u64 = 0xCA11;
pub const CALIBRATION_INSTANCES: u32 = 8;
pub const CALIBRATION_VIEWS: usize = 2;

/// How the mock part is calibrated.
#[derive(Clone, Debug)]
pub struct MockCalibrationSpec {
    pub part: Part,
    /// The calibration capture's image size, px, and samples per pixel of its renders.
    pub width_px: u32,
    pub height_px: u32,
    pub samples_per_pixel: u32,
    /// Adam iterations of the BSDF fit (0: the service's default, 300).
    pub fit_iterations: u32,
    /// The part's metallic weight when its finish is known (1: bare metal), held by the fit
    /// instead of fitted; `None`: fitted.
    pub known_metallic: Option<f64>,
    /// Start values of the BSDF fit, each in (0, 1), one fit per start, the best kept (empty:
    /// the service's default, 0.5).
    pub starts: Vec<f64>,
}

/// What the calibration reports while it runs.
pub enum CalibrationEvent<'a> {
    /// One calibration view recorded (of [`CALIBRATION_VIEWS`]).
    ViewRecorded,
    /// The response is solved: sample pixels used and the residual RMS, ln units.
    ResponseSolved { samples: u32, residual_rms: f64 },
    /// One iteration of the BSDF fit.
    FitProgress(&'a v1::FitProgress),
}

/// A part's calibration cache: `DIR/response.json`, `DIR/material.json` (written last: both
/// present means the calibration completed) and the capture they came from, `DIR/scene/`.
#[derive(Clone, Debug)]
pub struct CalibrationCache {
    pub dir: PathBuf,
}

impl CalibrationCache {
    /// The cache of `part` under `root` (`root/<part>/`).
    pub fn of_part(root: &Path, part: Part) -> Self {
        Self {
            dir: root.join(part.name()),
        }
    }

    pub fn response_path(&self) -> PathBuf {
        self.dir.join("response.json")
    }

    pub fn material_path(&self) -> PathBuf {
        self.dir.join("material.json")
    }

    pub fn scene_dir(&self) -> PathBuf {
        self.dir.join("scene")
    }

    /// The cached calibration: `None` when the cache holds none (or only part of one);
    /// an error when its files are there but unreadable, naming the file.
    pub fn load(&self) -> anyhow::Result<Option<Calibration>> {
        let (material, response) = (self.material_path(), self.response_path());
        if !(material.is_file() && response.is_file()) {
            return Ok(None);
        }
        Ok(Some(Calibration::load(&material, &response)?))
    }
}

/// An exposure stack as `CalibrateResponse`'s stream: the header, then every image's chunks
/// (each message under gRPC's default 4 MiB limit).
pub fn exposure_stack_messages(
    images: &[Image<u16>],
    exposures_s: &[f64],
    bit_depth: u32,
) -> Vec<v1::ExposureStackChunk> {
    use v1::exposure_stack_chunk::Part;
    let arrays: Vec<OutgoingArray> = images
        .iter()
        .enumerate()
        .map(|(i, img)| OutgoingArray::image(&format!("exposure_{i:03}"), v1::Image::from(img)))
        .collect();
    let header = v1::ExposureStackHeader {
        exposures_s: exposures_s.to_vec(),
        arrays: arrays.iter().map(|a| a.header.clone()).collect(),
        bit_depth,
        lambda: 0.0,
        samples: 0,
    };
    std::iter::once(v1::ExposureStackChunk {
        part: Some(Part::Header(header)),
    })
    .chain(chunks(&arrays).map(|c| v1::ExposureStackChunk {
        part: Some(Part::Chunk(c)),
    }))
    .collect()
}

/// Calibrates `spec.part` through the calibration service at `addr` into `cache`: records the
/// capture in `cache.scene_dir()` (replacing what an interrupted run left), then writes the
/// response and, last, the material. Callers read a complete cache with
/// [`CalibrationCache::load`] first; this calibrates anew whatever the cache holds.
pub async fn calibrate_mock_part(
    addr: &str,
    security: &ClientSecurity,
    spec: &MockCalibrationSpec,
    cache: &CalibrationCache,
    mut on_event: impl FnMut(CalibrationEvent<'_>),
) -> anyhow::Result<Calibration> {
    let scene_dir = cache.scene_dir();
    let (events_tx, mut events_rx) = tokio::sync::mpsc::unbounded_channel();
    let recording = {
        let (spec, scene_dir) = (spec.clone(), scene_dir.clone());
        tokio::task::spawn_blocking(move || {
            record_calibration_capture(&spec, &scene_dir, events_tx)
        })
    };
    while events_rx.recv().await.is_some() {
        on_event(CalibrationEvent::ViewRecorded);
    }
    recording
        .await
        .context("the calibration capture panicked")??;

    let mut client = CalibrationServiceClient::new(channel(addr, security).await?);
    let layout = BopSceneLayout::new(scene_dir.join("test").join("000001"));
    let stack_dir = layout.exposure_stack_dir(0);
    let stack = tokio::task::spawn_blocking(move || ExposureStackFiles::read(stack_dir))
        .await
        .context("reading the exposure stack panicked")??;
    let messages = exposure_stack_messages(
        &stack.images,
        &stack.exposures_s,
        u32::from(stack.bit_depth),
    );
    let solved = client
        .calibrate_response(tokio_stream::iter(messages))
        .await
        .map_err(status)
        .context("CalibrateResponse")?
        .into_inner();
    on_event(CalibrationEvent::ResponseSolved {
        samples: solved.samples_used,
        residual_rms: solved.residual_rms,
    });
    let curve = solved
        .response
        .context("CalibrateResponse answered without a response")?;
    let mut response = response_from_message(&curve).context("CalibrateResponse's response")?;
    response.solve.lambda = DebevecConfig::default().lambda;
    response.solve.samples = solved.samples_used as usize;
    response.solve.exposures_s = stack.exposures_s.clone();
    response.solve.rms_residual = solved.residual_rms;

    let mut events = client
        .fit_bsdf(v1::FitBsdfRequest {
            scene_dir: scene_dir.to_string_lossy().into_owned(),
            response: Some(response_to_message(&response)),
            views: (0..CALIBRATION_VIEWS as u32).collect(),
            iterations: spec.fit_iterations,
            starts: spec.starts.clone(),
            known_metallic: spec.known_metallic,
        })
        .await
        .map_err(status)
        .context("FitBsdf")?
        .into_inner();
    let mut result = None;
    while let Some(event) = events.message().await.map_err(status).context("FitBsdf")? {
        match event.event {
            Some(v1::fit_bsdf_event::Event::Progress(p)) => {
                on_event(CalibrationEvent::FitProgress(&p))
            }
            Some(v1::fit_bsdf_event::Event::Result(r)) => result = Some(r),
            None => {}
        }
    }
    let result = result.context("FitBsdf's stream ended without a result")?;
    let material = MaterialFile::parse(&result.material_file_json, Path::new("FitBsdf's result"))?;
    std::fs::create_dir_all(&cache.dir)
        .with_context(|| format!("creating {}", cache.dir.display()))?;
    response.save(&cache.response_path())?;
    material.save(&cache.material_path())?;
    Ok(Calibration { material, response })
}

/// Records the calibration capture into `scene_dir`: in a fresh folder beside it first, moved
/// into place once complete, so that `scene_dir` only ever holds a whole capture.
fn record_calibration_capture(
    spec: &MockCalibrationSpec,
    scene_dir: &Path,
    on_view: tokio::sync::mpsc::UnboundedSender<()>,
) -> anyhow::Result<()> {
    let partial = scene_dir.with_extension("partial");
    for dir in [&partial, &scene_dir.to_path_buf()] {
        if dir.exists() {
            std::fs::remove_dir_all(dir).with_context(|| format!("removing {}", dir.display()))?;
        }
    }
    let setup = BinSetup::new(
        &spec.part.mesh(),
        materials::ground_truth(spec.part),
        &BinSetupSpec {
            instances: CALIBRATION_INSTANCES,
            seed: CALIBRATION_SEED,
            width_px: spec.width_px,
            height_px: spec.height_px,
            samples_per_pixel: spec.samples_per_pixel,
        },
    )?;
    let views = setup.views(CALIBRATION_VIEWS);
    record_exposure_stacks(
        &partial,
        spec.part,
        &setup,
        CALIBRATION_SEED,
        &views,
        &CALIBRATION_EXPOSURES_S,
        || {
            // The receiver only counts views; one that went away needs no count.
            let _ = on_view.send(());
        },
    )?;
    std::fs::rename(&partial, scene_dir)
        .with_context(|| format!("moving {} to {}", partial.display(), scene_dir.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cache_holds_a_calibration_only_when_both_files_are_there_and_read() {
        let root = tempfile::tempdir().unwrap();
        let cache = CalibrationCache::of_part(root.path(), Part::Zigzag);
        assert!(cache.load().unwrap().is_none(), "an empty cache holds none");
        let shipped = Calibration::embedded(Part::Zigzag).unwrap();
        std::fs::create_dir_all(&cache.dir).unwrap();
        shipped.response.save(&cache.response_path()).unwrap();
        // An interrupted calibration wrote the response only: not a calibration.
        assert!(cache.load().unwrap().is_none());
        shipped.material.save(&cache.material_path()).unwrap();
        let loaded = cache.load().unwrap().unwrap();
        assert_eq!(loaded.material, shipped.material);
        assert_eq!(loaded.response.inverse, shipped.response.inverse);
        // A damaged file is an error naming it, never silently recalibrated over.
        std::fs::write(cache.material_path(), "{").unwrap();
        let e = cache.load().unwrap_err().to_string();
        assert!(e.contains("material.json"), "{e}");
    }

    #[test]
    fn an_exposure_stack_streams_as_a_header_then_chunks_under_the_default_limit() {
        let image = Image::new(1280, 1024, vec![7u16; 1280 * 1024]).unwrap();
        let messages = exposure_stack_messages(&[image.clone(), image], &[1e-3, 2e-3], 12);
        let Some(v1::exposure_stack_chunk::Part::Header(header)) = &messages[0].part else {
            panic!("the first message is not the header");
        };
        assert_eq!(header.arrays.len(), 2);
        assert_eq!(header.bit_depth, 12);
        assert!(
            messages[1..]
                .iter()
                .all(|m| matches!(m.part, Some(v1::exposure_stack_chunk::Part::Chunk(_))))
        );
        use prost::Message;
        let largest = messages.iter().map(|m| m.encoded_len()).max().unwrap();
        assert!(largest < 4 << 20, "a message of {largest} bytes");
    }
}
