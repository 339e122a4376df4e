//! `glint eval …`: the paper's experiments on mock-camera data (or any BOP scene).

mod active_exp;
mod camera_exp;
mod initial_pose_exp;
mod nbv_exp;
mod prediction_exp;
mod refine_exp;
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
    /// How well the render workers predict the depth pixels a view loses (eq 16–17) over a
    /// grid of τ_I and τ_σ: on tuning seeds to choose them, on evaluation seeds to judge.
    Prediction(prediction_exp::PredictionArgs),
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
