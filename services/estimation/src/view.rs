//! One view as a structured-light camera delivers it → the part's depth points with σ_z: the
//! input path every refinement takes (the Refine RPC, active sessions, the experiments' BOP
//! reader). Which pixels belong to the part comes from what a real system has: the silhouette
//! of the current pose hypothesis, dilated by its uncertainty, or a mask the client sends.

use glint_geometry::TriMesh;
use glint_geometry::camera::StereoRig;
use glint_geometry::image::{DepthMap, Image, normalised_intensity};
use glint_geometry::silhouette::{dilated, silhouette_mask};
use nalgebra::Isometry3;

use crate::depth_sigma::{DepthSigmaError, NoiseModel, depth_sigma};
use crate::points::{DepthPoint, DepthSigma, PointCounts, interior_mask, object_points};

/// One view's measurement: a rectified stereo capture of K pattern shots and its matched depth.
#[derive(Clone, Debug)]
pub struct ViewMeasurement {
    /// Left camera → world.
    pub t_w_c: Isometry3<f64>,
    /// The rectified rig of the left camera.
    pub stereo: StereoRig,
    /// Matched depth in the left camera, NaN where missing.
    pub depth: DepthMap,
    /// The K pattern shots, left and right, as read out (digital numbers, response encoded).
    pub left: Vec<Image<u16>>,
    /// The right camera's K pattern shots, in the same order as `left`.
    pub right: Vec<Image<u16>>,
    /// Two more read-outs of one static shot (σ_I's photon transfer), when the camera took them.
    pub noise_shots: Option<[Image<u16>; 2]>,
    /// Full scale of the digital numbers.
    pub max_dn: u16,
}

/// Where σ_z of each depth pixel comes from.
#[derive(Clone, Debug)]
pub enum SigmaSource {
    /// From the view's pattern images by eq 1–5, with the matcher's window radius (px) and
    /// the sensor's noise model (fitted from the view's noise shots when `None`).
    PatternImages {
        /// The matcher's window radius, px.
        window_radius_px: u32,
        /// The sensor's noise model; `None` fits it from the view's noise shots.
        noise: Option<NoiseModel>,
    },
    /// One σ_z for every pixel, metres: an unweighted refinement.
    Constant {
        /// The σ_z, metres.
        sigma_z_m: f64,
    },
}

/// Why a view gives no points.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ViewError {
    /// The view or its inputs do not fit together (a depth map, mask or σ image of another
    /// size than the camera's, no noise shots for σ_z from pattern images, a bad constant σ_z).
    #[error("{field}: {message}")]
    Input {
        /// The offending input: `depth`, `mask`, `sigma`, `noise_shots` or
        /// `constant_sigma_z_m`.
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// σ_z could not be computed from the view's images (see [`DepthSigmaError`]).
    #[error("σ_z: {0}")]
    Sigma(#[from] DepthSigmaError),
}

fn input(field: &'static str, message: impl Into<String>) -> ViewError {
    ViewError::Input {
        field,
        message: message.into(),
    }
}

/// What [`view_points`] found.
#[derive(Clone, Debug)]
pub struct ViewPoints {
    /// The part's depth points, world frame, with σ_z.
    pub points: Vec<DepthPoint>,
    /// What became of the mask's pixels; not updated by [`ViewPoints::drop_background`].
    pub counts: PointCounts,
}

/// The part's pixels in a view as a real system knows them: the silhouette of `mesh` at the
/// hypothesis `t_w_o` seen from `t_w_c`, grown by `margin_m` (metres at the object's depth:
/// the hypothesis may be off by that much; wrong pixels inside the grown mask are the
/// refiner's outliers to reject).
pub fn hypothesis_mask(
    mesh: &TriMesh,
    stereo: &StereoRig,
    t_w_c: &Isometry3<f64>,
    t_w_o: &Isometry3<f64>,
    margin_m: f64,
) -> Image<bool> {
    let t_c_o = t_w_c.inverse() * t_w_o;
    let depth_m = t_c_o.translation.z.max(1e-3);
    let k = &stereo.intrinsics;
    // A lateral offset `margin_m` at depth z moves the image by f·margin/z pixels.
    let margin_px = (k.fx_px.max(k.fy_px) * margin_m.max(0.0) / depth_m).ceil();
    dilated(
        &silhouette_mask(mesh, k, &t_c_o),
        margin_px.min(f64::from(k.width_px.max(k.height_px))) as u32,
    )
}

/// A plane of the scene known not to be the part — a bin's floor, a table — from the cell's
/// calibration: depth points on it or behind it are background, whatever mask they fall in.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BackgroundPlane {
    /// Unit normal, world frame, pointing to where the parts are.
    pub normal_w: nalgebra::Unit<nalgebra::Vector3<f64>>,
    /// `n · p_w` on the plane, metres.
    pub offset_m: f64,
    /// Points closer to the plane than this are background, metres (depth noise and the
    /// matcher's smoothing at the part's foot).
    pub clearance_m: f64,
}

impl BackgroundPlane {
    /// Whether `p_w` lies on the plane, within the clearance, or behind it.
    pub fn holds(&self, p_w: &nalgebra::Point3<f64>) -> bool {
        self.normal_w.dot(&p_w.coords) - self.offset_m < self.clearance_m
    }
}

/// The noise model of a view's noise shots (two read-outs of one static shot).
pub fn noise_model_of(view: &ViewMeasurement) -> Result<NoiseModel, ViewError> {
    let Some([a, b]) = &view.noise_shots else {
        return Err(input(
            "noise_shots",
            "σ_z from pattern images needs the sensor's noise model: capture the view with \
             noise shots or pass a noise model",
        ));
    };
    Ok(NoiseModel::fit_from_pair(
        &normalised_intensity(a, view.max_dn),
        &normalised_intensity(b, view.max_dn),
        view.max_dn,
    )?)
}

/// A view's σ_z per pixel (eq 1–5) or one σ_z for all: it depends on the view alone, not on
/// the pose hypothesis, so a caller that masks the view more than once computes it once.
#[derive(Clone, Debug)]
pub enum ViewSigma {
    /// σ_z of each pixel of the left depth, metres ([`depth_sigma`]: NaN where depth is
    /// missing or the window leaves the image, +∞ where the window has no gradient).
    PerPixel(Image<f32>),
    /// One σ_z for every pixel, metres.
    Constant(f64),
}

fn check_size(view: &ViewMeasurement) -> Result<(u32, u32), ViewError> {
    let (w, h) = (view.depth.depth_m.width(), view.depth.depth_m.height());
    let intrinsics = &view.stereo.intrinsics;
    if (w, h) != (intrinsics.width_px, intrinsics.height_px) {
        return Err(input(
            "depth",
            format!(
                "is {w}×{h} px but the rig's camera is {}×{} px",
                intrinsics.width_px, intrinsics.height_px
            ),
        ));
    }
    Ok((w, h))
}

/// σ_z of `view`'s depth pixels from `sigma`.
pub fn view_sigma(view: &ViewMeasurement, sigma: &SigmaSource) -> Result<ViewSigma, ViewError> {
    check_size(view)?;
    match sigma {
        SigmaSource::Constant { sigma_z_m } => {
            if !(sigma_z_m.is_finite() && *sigma_z_m > 0.0) {
                return Err(input(
                    "constant_sigma_z_m",
                    format!("is {sigma_z_m}; a depth σ must be finite and positive (metres)"),
                ));
            }
            Ok(ViewSigma::Constant(*sigma_z_m))
        }
        SigmaSource::PatternImages {
            window_radius_px,
            noise,
        } => {
            let noise = match noise {
                Some(n) => n.clone(),
                None => noise_model_of(view)?,
            };
            let normalised = |shots: &[Image<u16>]| -> Vec<Image<f32>> {
                shots
                    .iter()
                    .map(|s| normalised_intensity(s, view.max_dn))
                    .collect()
            };
            Ok(ViewSigma::PerPixel(depth_sigma(
                &normalised(&view.left),
                &normalised(&view.right),
                &view.depth,
                &view.stereo,
                &noise,
                *window_radius_px,
            )?))
        }
    }
}

/// The part's depth points of one view (world frame, with σ_z; eq 1–7): the pixels of `mask`
/// whose `(2·erode_px + 1)²` window lies inside it, with depth and a usable σ_z.
pub fn view_points(
    view: &ViewMeasurement,
    mask: &Image<bool>,
    sigma: &SigmaSource,
    erode_px: u32,
) -> Result<ViewPoints, ViewError> {
    points_in_mask(view, mask, &view_sigma(view, sigma)?, erode_px)
}

/// [`view_points`] with the view's σ_z already computed ([`view_sigma`]).
pub fn points_in_mask(
    view: &ViewMeasurement,
    mask: &Image<bool>,
    sigma: &ViewSigma,
    erode_px: u32,
) -> Result<ViewPoints, ViewError> {
    let (w, h) = check_size(view)?;
    if (mask.width(), mask.height()) != (w, h) {
        return Err(input(
            "mask",
            format!(
                "is {}×{} px but the depth is {w}×{h} px",
                mask.width(),
                mask.height()
            ),
        ));
    }
    let interior = interior_mask(w, h, erode_px, |u, v| mask.get(u, v).unwrap_or(false));
    let inside = |u: u32, v: u32| interior.get(u, v).unwrap_or(false);
    let depth_sigma = match sigma {
        ViewSigma::PerPixel(image) => {
            if (image.width(), image.height()) != (w, h) {
                return Err(input(
                    "sigma",
                    format!(
                        "is {}×{} px but the depth is {w}×{h} px",
                        image.width(),
                        image.height()
                    ),
                ));
            }
            DepthSigma::PerPixel(image)
        }
        ViewSigma::Constant(s) => DepthSigma::Constant(*s),
    };
    let mut points = Vec::new();
    let counts = object_points(
        &view.depth,
        inside,
        depth_sigma,
        &view.stereo.intrinsics,
        &view.t_w_c,
        &mut points,
    );
    Ok(ViewPoints { points, counts })
}

impl ViewPoints {
    /// Drops the points `background` holds; returns how many.
    pub fn drop_background(&mut self, background: &BackgroundPlane) -> usize {
        let before = self.points.len();
        self.points.retain(|p| !background.holds(&p.p_w));
        before - self.points.len()
    }
}
