//! Why depth went missing: the paper's Fig. 1 effects, attributed per pixel from the physics
//! of a capture (evaluation only: it reads the simulator's ground-truth renders).
//!
//! - **Saturation**: the left pattern image is clipped at full scale inside the matching
//!   window, so the dots are washed out (the right image is not checked: its window position
//!   needs the disparity that failed).
//! - **Low SNR**: the surface sends too little projector light to the camera (dark window).
//! - **Inter-reflection**: light reflected by other surfaces dominates the direct reflection,
//!   `I_single / I_multi < τ_I` (eq 16's criterion, here on ground truth).

use glint_geometry::image::Image;
use glint_render::integrator::{LightTransport, RenderSettings, render};
use glint_render::stereo::MatchStatus;

use crate::capture::{CaptureTruth, MockSliCamera, StereoCapture};

/// Counts of missing pixels on one instance by cause (a pixel can have several causes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MissingCauses {
    /// Pixels of the instance.
    pub pixels: usize,
    /// Of those, without depth.
    pub missing: usize,
    pub saturated: usize,
    pub low_snr: usize,
    pub inter_reflection: usize,
    /// Missing for none of the three (occlusion in the right view, window straddling an edge, …).
    pub other: usize,
}

/// Direct share below which a pixel counts as dominated by inter-reflection (τ_I of eq 16).
pub const INTER_REFLECTION_RATIO: f32 = 0.6;
/// Window mean below which a pixel counts as dark: 4 % of full scale.
pub const DARK_FRACTION: f32 = 0.04;

/// Attributes the missing depth of instance `label` in `capture` (taken by `camera`, with
/// ground truth `truth`).
pub fn missing_causes(
    camera: &MockSliCamera<'_>,
    capture: &StereoCapture,
    truth: &CaptureTruth,
    label: u16,
    seed: u64,
) -> MissingCauses {
    let [left, _] = camera.rig.cameras(&capture.t_w_c);
    let projector = camera.rig.projector(&capture.t_w_c, camera.pattern());
    let single = render(
        camera.scene,
        &left,
        &projector,
        &RenderSettings {
            transport: LightTransport::SinglePath,
            samples_per_pixel: camera.config.samples_per_pixel,
            roi: None,
            seed,
        },
    )
    .radiance;
    let max_dn = camera.config.sensor.max_dn();
    let r = camera.config.matcher.window_radius_px as i64;
    let (w, h) = (capture.left.width() as i64, capture.left.height() as i64);
    let window = |img: &Image<u16>, u: i64, v: i64| {
        let (mut clipped, mut sum, mut n) = (false, 0u64, 0u64);
        for y in (v - r).max(0)..(v + r + 1).min(h) {
            for x in (u - r).max(0)..(u + r + 1).min(w) {
                let d = img.get(x as u32, y as u32).unwrap_or(0);
                clipped |= d >= max_dn;
                sum += d as u64;
                n += 1;
            }
        }
        (clipped, sum as f32 / n.max(1) as f32 / max_dn as f32)
    };
    let mut causes = MissingCauses::default();
    for v in 0..h {
        for u in 0..w {
            if truth.label.get(u as u32, v as u32) != Some(label) {
                continue;
            }
            causes.pixels += 1;
            if capture.match_status.get(u as u32, v as u32) == Some(MatchStatus::Valid) {
                continue;
            }
            causes.missing += 1;
            let (clipped, mean) = window(&capture.left, u, v);
            let direct = single.get(u as u32, v as u32).unwrap_or(0.0);
            let total = truth.left_radiance.get(u as u32, v as u32).unwrap_or(0.0);
            let saturated = clipped;
            let low_snr = !clipped && mean < DARK_FRACTION;
            let inter = total > 0.0 && direct / total < INTER_REFLECTION_RATIO;
            causes.saturated += saturated as usize;
            causes.low_snr += low_snr as usize;
            causes.inter_reflection += inter as usize;
            causes.other += (!saturated && !low_snr && !inter) as usize;
        }
    }
    causes
}
