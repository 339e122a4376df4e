//! Why depth went missing, and why accepted depth is wrong: the paper's Fig. 1 effects,
//! attributed per pixel from the physics of a capture (evaluation only: it reads the
//! simulator's ground-truth renders).
//!
//! - **Saturation**: the left pattern image is clipped at full scale inside the matching
//!   window, so the dots are washed out (the right image is not checked: its window position
//!   needs the disparity that failed).
//! - **Low SNR**: the surface sends too little projector light to the camera (dark window).
//! - **Inter-reflection**: light reflected by other surfaces dominates the direct reflection,
//!   `I_single / I_multi < τ_I` (eq 16's criterion, here on ground truth).

use glint_geometry::image::{DepthMap, Image};
use glint_render::integrator::{LightTransport, RenderSettings, render};
use glint_render::projector::Pattern;
use glint_render::stereo::MatchStatus;

use crate::capture::{CaptureTruth, MockSliCamera, StereoCapture};

/// Counts of missing pixels on one instance by cause (a pixel can have several causes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MissingCauses {
    /// Pixels of the instance.
    pub pixels: usize,
    /// Of those, without depth.
    pub missing: usize,
    /// Of the missing, those whose left-image matching window holds a pixel clipped at full
    /// scale.
    pub saturated: usize,
    /// Of the missing, those not clipped whose window mean is below [`DARK_FRACTION`] of full
    /// scale.
    pub low_snr: usize,
    /// Of the missing, those whose direct share `I_single / I_multi` is below
    /// [`INTER_REFLECTION_RATIO`] (τ_I of eq 16).
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

/// Accepted depth farther than this from the true surface counts as wrong, metres.
pub const WRONG_DEPTH_M: f64 = 2e-3;

/// Accepted depth on the parts that lies more than [`WRONG_DEPTH_M`] off the true surface, by
/// cause. Each wrong pixel takes the first cause that applies, in the order of the fields.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WrongDepthCauses {
    /// Part pixels with accepted depth.
    pub valid: usize,
    /// Of those, more than [`WRONG_DEPTH_M`] off the true surface.
    pub wrong: usize,
    /// The matching window (radius r) holds a true depth edge: its texture mixes two surfaces.
    pub edge: usize,
    /// The window is clipped at full scale in some shot's left image.
    pub saturated: usize,
    /// Inter-reflected light dominates (`I_single / I_multi <` [`INTER_REFLECTION_RATIO`]
    /// under the white pattern) and the depth lies behind the true surface: the matcher found
    /// the virtual image of another surface mirrored in this one.
    pub mirror_image: usize,
    /// Inter-reflected light dominates and the depth lies in front of the true surface: a
    /// blend of the direct and the reflected texture.
    pub inter_reflection: usize,
    /// Direct light dominates, no edge, no clipping: sensor noise, low texture, or a direct
    /// share above the ratio that still shifts the match.
    pub other: usize,
}

impl WrongDepthCauses {
    /// Adds `other`'s counts to these.
    pub fn add(&mut self, other: &Self) {
        self.valid += other.valid;
        self.wrong += other.wrong;
        self.edge += other.edge;
        self.saturated += other.saturated;
        self.mirror_image += other.mirror_image;
        self.inter_reflection += other.inter_reflection;
        self.other += other.other;
    }
}

/// Per left pixel, the direct share of the light under the white pattern,
/// `I_single / I_multi` (eq 16's ratio on ground truth; NaN where the multi-path radiance is
/// 0). Two renders of the left camera from rig pose `t_w_c` at the camera's samples per pixel.
pub fn direct_share(
    camera: &MockSliCamera<'_>,
    t_w_c: &nalgebra::Isometry3<f64>,
    seed: u64,
) -> Image<f32> {
    let [left, _] = camera.rig.cameras(t_w_c);
    let projector = camera.rig.projector(t_w_c, Pattern::White);
    let radiance = |transport| {
        render(
            camera.scene,
            &left,
            &projector,
            &RenderSettings {
                transport,
                samples_per_pixel: camera.config.samples_per_pixel,
                roi: None,
                seed,
            },
        )
        .radiance
    };
    let single = radiance(LightTransport::SinglePath);
    let multi = radiance(camera.config.transport);
    // Both renders come from one camera, so their sizes agree.
    single
        .zip_map(&multi, |s, m| if m > 0.0 { s / m } else { f32::NAN })
        .unwrap_or_else(|| Image::filled_like(&multi, f32::NAN))
}

/// Attributes the wrong accepted depth of one capture's part pixels. `surface_distance_m[i]`
/// is |depth point → true model surface| of pixel i (NaN where it has no depth or is no part
/// pixel); `depth` is the matched depth, `truth` the capture's ground truth, `edge_px` the
/// pixels' L∞ distance to the nearest true depth edge
/// ([`crate::edge_errors::distance_to_depth_edge`]), `direct_share` from [`direct_share`],
/// `left_shots` the read-out left images of every shot (digital numbers of full scale
/// `max_dn`), `window_radius_px` the matcher's window radius.
#[allow(clippy::too_many_arguments)]
pub fn wrong_depth_causes(
    surface_distance_m: &[f64],
    depth: &DepthMap,
    truth: &CaptureTruth,
    edge_px: &Image<u32>,
    direct_share: &Image<f32>,
    left_shots: &[&Image<u16>],
    max_dn: u16,
    window_radius_px: u32,
) -> WrongDepthCauses {
    let (w, h) = (depth.depth_m.width() as i64, depth.depth_m.height() as i64);
    let r = window_radius_px as i64;
    let clipped = |u: i64, v: i64| {
        left_shots.iter().any(|img| {
            ((v - r).max(0)..(v + r + 1).min(h)).any(|y| {
                ((u - r).max(0)..(u + r + 1).min(w))
                    .any(|x| img.get(x as u32, y as u32).is_some_and(|d| d >= max_dn))
            })
        })
    };
    let mut causes = WrongDepthCauses::default();
    for (i, &distance) in surface_distance_m.iter().enumerate() {
        if !distance.is_finite() {
            continue;
        }
        causes.valid += 1;
        if distance <= WRONG_DEPTH_M {
            continue;
        }
        causes.wrong += 1;
        let (u, v) = (i as i64 % w, i as i64 / w);
        let share = direct_share.data()[i];
        if edge_px.data()[i] <= window_radius_px {
            causes.edge += 1;
        } else if clipped(u, v) {
            causes.saturated += 1;
        } else if share.is_finite() && share < INTER_REFLECTION_RATIO {
            if depth.depth_m.data()[i] > truth.depth_m.data()[i] {
                causes.mirror_image += 1;
            } else {
                causes.inter_reflection += 1;
            }
        } else {
            causes.other += 1;
        }
    }
    causes
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 9×1 strip: an edge at pixel 0 (u = 0 holds a step), a clipped pixel at u = 4, and
    /// direct shares that make u = 6 and u = 7 inter-reflected, one behind and one in front.
    #[test]
    fn each_wrong_pixel_takes_the_first_cause_that_applies() {
        let width = 9;
        let image = |data: Vec<f32>| Image::new(width, 1, data).expect("9 pixels");
        let true_depth = image(vec![0.50; 9]);
        let truth = CaptureTruth {
            left_radiance: image(vec![1.0; 9]),
            depth_m: true_depth.clone(),
            label: Image::filled(width, 1, 1u16).expect("9 pixels"),
        };
        // Measured: behind the truth at u = 6, in front at u = 7.
        let mut measured = vec![0.50f32; 9];
        measured[6] = 0.52;
        measured[7] = 0.48;
        let depth = DepthMap::new(image(measured));
        // Surface distances: u = 2 is right (1 mm), u = 8 has no depth; every other pixel is
        // 5 mm off.
        let mut distance = vec![5e-3; 9];
        distance[2] = 1e-3;
        distance[8] = f64::NAN;
        let edge = Image::new(width, 1, (0..9).map(|u| u as u32).collect()).expect("9 pixels");
        let mut share = vec![1.0f32; 9];
        share[5] = 0.9;
        share[6] = 0.3;
        share[7] = 0.3;
        let share = image(share);
        let mut dn = vec![100u16; 9];
        dn[4] = 255;
        let left = Image::new(width, 1, dn).expect("9 pixels");
        let causes = wrong_depth_causes(&distance, &depth, &truth, &edge, &share, &[&left], 255, 0);
        // Window radius 0: u = 0 is on the edge; u = 1, 3, 5 are "other"; u = 4 is clipped.
        assert_eq!(
            causes,
            WrongDepthCauses {
                valid: 8,
                wrong: 7,
                edge: 1,
                saturated: 1,
                mirror_image: 1,
                inter_reflection: 1,
                other: 3,
            }
        );
        // Radius 1: the windows of u = 1 reach the edge distance bound (edge_px ≤ 1), and
        // those of u = 3 and u = 5 hold the clipped pixel.
        let wide = wrong_depth_causes(&distance, &depth, &truth, &edge, &share, &[&left], 255, 1);
        assert_eq!((wide.edge, wide.saturated, wide.other), (2, 3, 0));
        assert_eq!((wide.mirror_image, wide.inter_reflection), (1, 1));
    }
}
