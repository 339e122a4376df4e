//! `glint eval …`: the paper's experiments on mock-camera data (or any BOP scene).

mod active_exp;
mod camera_exp;
mod initial_pose_exp;
mod nbv_exp;
mod prediction_exp;
mod refine_exp;
mod thresholds_exp;
mod uncertainty_exp;

#[derive(clap::Subcommand)]
pub enum EvalCommand {
    /// Table I: SDF refinement (ours) against ICP from the same initial poses and depth, at
    /// 1, 2 and 4 views.
    Refine(Box<refine_exp::RefineArgs>),
    /// Fig. 3: predicted depth σ_z (eq 1–5) against the measured spread of depth over
    /// repeated captures of a static scene.
    Uncertainty(uncertainty_exp::UncertaintyArgs),
    /// The mock camera against known geometry: depth-point distance to the true surface per
    /// shot count K and window size, on each part's diffuse twin and shiny material, by
    /// distance to depth edges, and a plane at 0.6 m.
    Camera(camera_exp::CameraArgs),
    /// Fig. 9 as the paper measures it: every view policy (NBV, NBV with constant σ_z,
    /// Random, Max-Distance) chooses every view among the same candidates, from the same
    /// detector guesses, on shared captures; rates at 5 mm/5° and 2 mm/2° against views.
    Nbv(Box<nbv_exp::NbvArgs>),
    /// Active sessions (the demo's loop) with each view policy (NBV, NBV with constant σ_z, Random,
    /// Max-Distance) from the same detector poses; error and entropy against views.
    Active(active_exp::ActiveArgs),
    /// Is the prediction right? For every candidate view, the render workers' prediction
    /// against the mock camera's capture: IoU of the missing masks, Spearman ρ of σ̌_z against
    /// the capture's σ_z, log-det ratio of the Fisher informations, and the oracle rank of the
    /// predicted best view; Fig. 8's images for one view of each part.
    Prediction(Box<prediction_exp::PredictionArgs>),
    /// The thresholds τ_I and τ_σ (eq 16–17): how well the predicted missing pixels match the
    /// capture's lost ones over a grid of both, on tuning seeds to choose them.
    Thresholds(thresholds_exp::ThresholdsArgs),
    /// The initial-pose distribution fitted to the paper's initial row of Table I (21.3 % at
    /// 5 mm/5°, 1.77 % at 2 mm/2° on `all`), and its rates per part against the paper's.
    InitialPoses(initial_pose_exp::InitialPosesArgs),
}

pub fn run(command: EvalCommand) -> anyhow::Result<()> {
    match command {
        EvalCommand::Refine(args) => refine_exp::run(&args),
        EvalCommand::Uncertainty(args) => uncertainty_exp::run_cmd(&args),
        EvalCommand::Camera(args) => camera_exp::run_cmd(&args),
        EvalCommand::Nbv(args) => nbv_exp::run_cmd(&args),
        EvalCommand::Active(args) => active_exp::run_cmd(&args),
        EvalCommand::Prediction(args) => prediction_exp::run_cmd(&args),
        EvalCommand::Thresholds(args) => thresholds_exp::run_cmd(&args),
        EvalCommand::InitialPoses(args) => initial_pose_exp::run(&args),
    }
}

/// `--parts`: `all` or a comma-separated list of part names.
pub fn parse_parts(text: &str) -> anyhow::Result<Vec<glint_geometry::Part>> {
    if text == "all" {
        return Ok(glint_geometry::Part::ALL.to_vec());
    }
    text.split(',')
        .map(|s| {
            s.trim()
                .parse::<glint_geometry::Part>()
                .map_err(anyhow::Error::msg)
        })
        .collect()
}

/// The bin and camera of the studies that set up their own mock bins per seed.
#[derive(clap::Args)]
pub struct BinArgs {
    /// Parts per bin.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub instances: u32,
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub spp: u32,
}

/// The mock camera's flags of the experiments that capture as they go.
#[derive(clap::Args)]
pub struct MockCameraArgs {
    /// Camera resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    /// Samples per pixel of the mock camera's renders.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub spp: u32,
    /// Patterns the mock camera projects per view.
    #[arg(long, default_value_t = glint_camera::capture::DEFAULT_SHOTS, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub shots: u32,
    /// The mock camera's matching window radius, px (default: the camera's for --shots).
    #[arg(long)]
    pub window_radius_px: Option<u32>,
}

impl MockCameraArgs {
    pub fn spec(&self) -> glint_eval::scenes::MockCameraSpec {
        glint_eval::scenes::MockCameraSpec {
            resolution: self.resolution,
            spp: self.spp,
            shots: self.shots,
            window_radius_px: self
                .window_radius_px
                .unwrap_or_else(|| glint_camera::capture::default_window_radius_px(self.shots)),
        }
    }
}

/// Each of `objects` (made from `parts`, or from a mesh when `mesh`) with its calibration:
/// the calibration flags' for a part; for a mesh, the files --material and --response name
/// (clap requires them with --mesh).
pub fn calibrated_objects(
    objects: Vec<glint_eval::scenes::EvalObject>,
    parts: &[glint_geometry::Part],
    calibration: &crate::calibration_args::PartCalibrationArgs,
    mesh: bool,
) -> anyhow::Result<Vec<glint_eval::scenes::CalibratedObject>> {
    use anyhow::Context;
    if calibration.one.material.is_some() && !mesh && parts.len() != 1 {
        anyhow::bail!(
            "--material and --response calibrate one part: give one --parts, or use \
             --calibrations DIR for several"
        );
    }
    objects
        .into_iter()
        .enumerate()
        .map(|(i, object)| {
            let part = parts.get(i).copied().filter(|_| !mesh);
            let calibration = match part {
                Some(part) => calibration
                    .load(part)
                    .with_context(|| format!("the {}'s calibration", part.display_name()))?,
                None => calibration.one.load(glint_geometry::Part::TubeFitting)?,
            };
            Ok(glint_eval::scenes::CalibratedObject {
                object,
                calibration,
            })
        })
        .collect()
}

/// An `--error-model`-style flag's value for `part` (`None`: a mesh): `none` (eq 18's
/// independent pixels), `shipped` (assets/calibration/<part>/pose_error.json) or a file
/// `glint eval refine` wrote (`DIR/pose_error/<part>.json`).
pub fn error_model_arg(
    flag: &str,
    value: &str,
    part: Option<glint_geometry::Part>,
) -> anyhow::Result<Option<glint_estimation::pose_error_model::PoseErrorModel>> {
    use anyhow::Context;
    use glint_estimation::pose_error_model::PoseErrorModel;
    match (value, part) {
        ("none", _) => Ok(None),
        ("shipped", Some(part)) => Ok(Some(
            PoseErrorModel::shipped(part).with_context(|| format!("{flag} shipped"))?,
        )),
        ("shipped", None) => anyhow::bail!(
            "{flag} shipped: Glint ships error models for its five parts only; give a file \
             `glint eval refine --mesh …` wrote (DIR/pose_error/<part>.json)"
        ),
        (path, _) => Ok(Some(
            PoseErrorModel::load(std::path::Path::new(path)).with_context(|| flag.to_string())?,
        )),
    }
}
