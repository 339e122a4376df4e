//! The calibration stage's gRPC server (`glint.v1.CalibrationService`): decode and validate the
//! request, run the library on the blocking pool, encode. Errors map to codes: bad input →
//! INVALID_ARGUMENT naming the field; a stack with too few well-exposed pixels →
//! FAILED_PRECONDITION.
//!
//! `FitBsdf` reads a capture on the server's disk in glint-camera's formats, which this crate
//! cannot depend on: it is served by a [`CalibrationServer`] built with a [`CaptureReader`]
//! ([`Calibration::with_capture_reader`]); plain [`Calibration`] answers UNIMPLEMENTED.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::pin::Pin;
use std::sync::Arc;

use glint_geometry::image::Image;
use glint_proto::chunks::{ArrayAssembler, AssembledArray};
use glint_proto::v1;
use glint_proto::v1::calibration_service_server::{CalibrationService, CalibrationServiceServer};
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

use crate::bsdf_fit::FitError;
use crate::bsdf_fit::scene_fit::{
    CaptureReader, SceneFitConfig, SceneFitError, fit_scene, read_capture,
};

use crate::material_file::MaterialFile;
use crate::response::{
    DebevecConfig, ExposureStack, ForwardTable, InverseTable, ResponseError, ResponseTable,
    SolveInfo, calibrate,
};

/// The service's name, as health reports it.
pub const SERVICE_NAME: &str = "glint.v1.CalibrationService";

/// The calibration service without a capture reader: `CalibrateResponse` only (`FitBsdf`
/// answers UNIMPLEMENTED).
#[derive(Clone, Debug, Default)]
pub struct Calibration;

impl Calibration {
    /// The tonic service to add to a server's routes.
    pub fn into_service(self) -> CalibrationServiceServer<CalibrationServer> {
        CalibrationServer { captures: None }.into_service()
    }

    /// The service with `FitBsdf` reading captures through `reader`.
    pub fn with_capture_reader(self, reader: Arc<dyn CaptureReader>) -> CalibrationServer {
        CalibrationServer {
            captures: Some(reader),
        }
    }
}

/// The calibration service; stateless but for the capture reader of `FitBsdf`.
#[derive(Clone)]
pub struct CalibrationServer {
    captures: Option<Arc<dyn CaptureReader>>,
}

impl CalibrationServer {
    /// The tonic service to add to a server's routes.
    pub fn into_service(self) -> CalibrationServiceServer<Self> {
        CalibrationServiceServer::new(self)
    }
}

/// Adam iterations when a request gives 0.
pub const DEFAULT_FIT_ITERATIONS: usize = 300;
/// The most Adam iterations a request may ask for; more is INVALID_ARGUMENT.
pub const MAX_FIT_ITERATIONS: usize = 10_000;
/// Progress messages buffered for a slow client before the fit waits.
const FIT_EVENTS_BUFFERED: usize = 16;

/// A validated FitBsdf request: the capture folder, the response, the fit's settings
/// (the library's defaults, which are `glint calibrate bsdf`'s, but views, iterations and
/// starts). Rejections name the field.
pub fn fit_request(
    msg: &v1::FitBsdfRequest,
) -> Result<(PathBuf, ResponseTable, SceneFitConfig), Status> {
    if msg.scene_dir.is_empty() {
        return Err(Status::invalid_argument("scene_dir: is empty"));
    }
    let dir = PathBuf::from(&msg.scene_dir);
    if let Err(e) = std::fs::read_dir(&dir) {
        return Err(Status::invalid_argument(format!(
            "scene_dir: {} is not a readable directory on the server: {e}",
            dir.display()
        )));
    }
    let response = msg
        .response
        .as_ref()
        .ok_or_else(|| Status::invalid_argument("response: is required"))?;
    let table = response_from_message(response).map_err(|e| Status::from(e.within("response")))?;
    let iterations = match msg.iterations as usize {
        0 => DEFAULT_FIT_ITERATIONS,
        n if n > MAX_FIT_ITERATIONS => {
            return Err(Status::invalid_argument(format!(
                "iterations: is {n}, but at most {MAX_FIT_ITERATIONS}"
            )));
        }
        n => n,
    };
    if let Some(i) = msg.starts.iter().position(|s| !(*s > 0.0 && *s < 1.0)) {
        return Err(Status::invalid_argument(format!(
            "starts[{i}]: is {}, but must be in (0, 1)",
            msg.starts[i]
        )));
    }
    if let Some(m) = msg.known_metallic
        && !(0.0..=1.0).contains(&m)
    {
        return Err(Status::invalid_argument(format!(
            "known_metallic: is {m}, but must be in [0, 1] (1: bare metal, 0: a dielectric)"
        )));
    }
    let defaults = SceneFitConfig::default();
    let config = SceneFitConfig {
        known_metallic: msg.known_metallic.map(|m| m as f32),
        views: msg.views.clone(),
        iterations,
        starts: if msg.starts.is_empty() {
            defaults.starts.clone()
        } else {
            msg.starts.iter().map(|&s| s as f32).collect()
        },
        ..defaults
    };
    Ok((dir, table, config))
}

fn fit_status(e: SceneFitError) -> Status {
    match &e {
        SceneFitError::Capture { .. } | SceneFitError::Stack { .. } => {
            Status::invalid_argument(format!("scene_dir: {e}"))
        }
        SceneFitError::NoView { index, .. } | SceneFitError::RepeatedView { index, .. } => {
            Status::invalid_argument(format!("views[{index}]: {e}"))
        }
        SceneFitError::NoDefaultViews { .. } => Status::invalid_argument(format!("views: {e}")),
        SceneFitError::Radiance { .. } => Status::invalid_argument(format!("response: {e}")),
        SceneFitError::Target { .. } | SceneFitError::Fit(FitError::NoPixels { .. }) => {
            Status::failed_precondition(e.to_string())
        }
        SceneFitError::Fit(FitError::Stopped { .. }) => Status::cancelled(e.to_string()),
        SceneFitError::Fit(_) => Status::internal(e.to_string()),
    }
}

/// A response table as its message.
pub fn response_to_message(table: &ResponseTable) -> v1::ResponseCurve {
    v1::ResponseCurve {
        bit_depth: u32::from(table.bit_depth),
        max_dn: u32::from(table.max_dn),
        inverse_dn: table.inverse.dn.clone(),
        inverse_ln_exposure: table.inverse.ln_exposure.clone(),
        forward_ln_exposure: table.forward.ln_exposure.clone(),
        forward_intensity: table.forward.intensity.clone(),
    }
}

/// A response message as the table it describes, validated (the inverse of
/// [`response_to_message`] but for the solve's provenance, which the message does not carry:
/// it comes back zero). Rejections name the field.
pub fn response_from_message(
    msg: &v1::ResponseCurve,
) -> Result<ResponseTable, glint_proto::ConversionError> {
    use glint_proto::ConversionError as E;
    let bit_depth = u8::try_from(msg.bit_depth)
        .ok()
        .filter(|b| (8..=16).contains(b))
        .ok_or_else(|| {
            E::new(
                "bit_depth",
                format!("is {}, but must be 8 to 16", msg.bit_depth),
            )
        })?;
    let max_dn = crate::response::max_dn(bit_depth);
    if msg.max_dn != u32::from(max_dn) {
        return Err(E::new(
            "max_dn",
            format!("is {}, but {bit_depth} bits have {max_dn}", msg.max_dn),
        ));
    }
    let levels = crate::response::debevec_levels(max_dn);
    let finite =
        |field: &'static str, values: &[f64]| match values.iter().position(|v| !v.is_finite()) {
            Some(i) => Err(E::new(
                field,
                format!("value {i} is {}, not finite", values[i]),
            )),
            None => Ok(()),
        };
    for (field, values) in [
        ("inverse_dn", &msg.inverse_dn),
        ("inverse_ln_exposure", &msg.inverse_ln_exposure),
    ] {
        if values.len() != levels {
            return Err(E::new(
                field,
                format!(
                    "has {} values, but a {bit_depth}-bit response has {levels} levels",
                    values.len()
                ),
            ));
        }
        finite(field, values)?;
    }
    let forward = ForwardTable {
        ln_exposure: msg.forward_ln_exposure.clone(),
        intensity: msg.forward_intensity.clone(),
    };
    crate::response::check_forward(&forward)
        .map_err(|(field, problem)| E::new(format!("forward_{field}"), problem))?;
    Ok(ResponseTable {
        format: crate::response::RESPONSE_FORMAT.to_owned(),
        bit_depth,
        max_dn,
        inverse: InverseTable {
            dn: msg.inverse_dn.clone(),
            ln_exposure: msg.inverse_ln_exposure.clone(),
        },
        forward,
        solve: SolveInfo {
            lambda: 0.0,
            samples: 0,
            exposures_s: Vec::new(),
            rms_residual: 0.0,
        },
    })
}

fn status_of(e: ResponseError) -> Status {
    match e {
        ResponseError::Input(message) => Status::invalid_argument(message),
        ResponseError::NoUsablePixels { .. } => Status::failed_precondition(e.to_string()),
        other => Status::internal(other.to_string()),
    }
}

/// Reads a whole exposure-stack stream: its header, then every declared image.
async fn read_stack(
    mut stream: Streaming<v1::ExposureStackChunk>,
) -> Result<(ExposureStack, DebevecConfig), Status> {
    use v1::exposure_stack_chunk::Part;
    let header = match stream.next().await {
        Some(Ok(v1::ExposureStackChunk {
            part: Some(Part::Header(h)),
        })) => h,
        Some(Ok(_)) => {
            return Err(Status::invalid_argument(
                "header: the stream must start with an ExposureStackHeader",
            ));
        }
        Some(Err(status)) => return Err(status),
        None => return Err(Status::invalid_argument("header: the stream is empty")),
    };
    let bit_depth = u8::try_from(header.bit_depth)
        .ok()
        .filter(|b| (1..=16).contains(b))
        .ok_or_else(|| {
            Status::invalid_argument(format!(
                "header.bit_depth: is {}, but must be 1 to 16",
                header.bit_depth
            ))
        })?;
    let defaults = DebevecConfig::default();
    let config = DebevecConfig {
        lambda: if header.lambda == 0.0 {
            defaults.lambda
        } else {
            header.lambda
        },
        samples: if header.samples == 0 {
            defaults.samples
        } else {
            header.samples as usize
        },
    };
    let mut assembler =
        ArrayAssembler::new(header.arrays, "header.arrays").map_err(Status::from)?;
    while let Some(message) = stream.next().await {
        match message?.part {
            Some(Part::Chunk(chunk)) => assembler.push(chunk).map_err(Status::from)?,
            _ => {
                return Err(Status::invalid_argument(
                    "header: only one header, first; then chunks",
                ));
            }
        }
    }
    let mut images = Vec::new();
    for (i, (_, array)) in assembler.finish()?.into_iter().enumerate() {
        let field = |e: glint_proto::ConversionError| e.within(&format!("header.arrays[{i}]"));
        let image: Image<u16> = match array {
            AssembledArray::Image(msg) if msg.encoding == v1::ImageEncoding::Mono8 as i32 => {
                Image::<u8>::try_from(msg).map_err(field)?.map(u16::from)
            }
            AssembledArray::Image(msg) => Image::<u16>::try_from(msg).map_err(field)?,
            AssembledArray::Depth(_) => {
                return Err(Status::invalid_argument(format!(
                    "header.arrays[{i}]: an exposure stack holds images, not depth maps"
                )));
            }
        };
        images.push(image);
    }
    let stack = ExposureStack::new(images, header.exposures_s, bit_depth).map_err(status_of)?;
    Ok((stack, config))
}

type FitStream = Pin<Box<dyn Stream<Item = Result<v1::FitBsdfEvent, Status>> + Send>>;

#[tonic::async_trait]
impl CalibrationService for CalibrationServer {
    async fn calibrate_response(
        &self,
        request: Request<Streaming<v1::ExposureStackChunk>>,
    ) -> Result<Response<v1::CalibrateResponseResponse>, Status> {
        let (stack, config) = read_stack(request.into_inner()).await?;
        let table = glint_server::blocking(move || calibrate(&stack, &config))
            .await?
            .map_err(status_of)?;
        Ok(Response::new(v1::CalibrateResponseResponse {
            response: Some(response_to_message(&table)),
            samples_used: table.solve.samples as u32,
            residual_rms: table.solve.rms_residual,
        }))
    }

    type FitBsdfStream = FitStream;

    async fn fit_bsdf(
        &self,
        request: Request<v1::FitBsdfRequest>,
    ) -> Result<Response<Self::FitBsdfStream>, Status> {
        let Some(reader) = self.captures.clone() else {
            return Err(Status::unimplemented(
                "FitBsdf: this server was built without a capture reader; run `glint calibrate bsdf` on the capture",
            ));
        };
        let (dir, table, config) = fit_request(request.get_ref())?;
        // Read the capture and check the views before the stream starts, so that bad input is
        // the call's status.
        let capture = {
            let (reader, views) = (reader.clone(), config.views.clone());
            glint_server::blocking(move || {
                let capture = read_capture(reader.as_ref(), &dir)?;
                capture.fitted_views(&views)?;
                Ok(capture)
            })
            .await?
            .map_err(fit_status)?
        };
        let (tx, rx) = tokio::sync::mpsc::channel(FIT_EVENTS_BUFFERED);
        tokio::task::spawn_blocking(move || {
            use v1::fit_bsdf_event::Event;
            let fitted = fit_scene(reader.as_ref(), capture, &table, &config, |p| {
                let event = v1::FitBsdfEvent {
                    event: Some(Event::Progress(v1::FitProgress {
                        iteration: p.iteration as u32,
                        iterations_total: p.iterations_total as u32,
                        loss: p.loss,
                        params: Some(v1::PrincipledMaterial::from(&p.params)),
                    })),
                };
                // A client that went away stops the fit.
                match tx.blocking_send(Ok(event)) {
                    Ok(()) => ControlFlow::Continue(()),
                    Err(_) => ControlFlow::Break(()),
                }
            });
            let last = fitted.map_err(fit_status).and_then(|fit| {
                let file = MaterialFile::new(&fit.result.params, fit.provenance.clone());
                let material_file_json = serde_json::to_string_pretty(&file)
                    .map_err(|e| Status::internal(format!("encoding the material file: {e}")))?;
                Ok(v1::FitBsdfEvent {
                    event: Some(Event::Result(v1::FitBsdfResult {
                        material: Some(v1::PrincipledMaterial::from(&fit.result.params)),
                        final_loss: fit.result.loss.last().copied().unwrap_or(f64::NAN),
                        judged_l2: fit.judged_l2,
                        elapsed_s: fit.elapsed_s,
                        material_file_json,
                        radiometric_scale: file.radiometric_scale().unwrap_or(f64::NAN),
                    })),
                })
            });
            // Nobody to tell if the client went away.
            let _ = tx.blocking_send(last);
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> ResponseTable {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../assets/calibration/zigzag/response.json");
        ResponseTable::load(&path).unwrap()
    }

    #[test]
    fn response_messages_round_trip_and_name_bad_fields() {
        let table = shipped();
        let msg = response_to_message(&table);
        let back = response_from_message(&msg).unwrap();
        assert_eq!(back.inverse, table.inverse);
        assert_eq!(back.forward, table.forward);
        assert_eq!(
            (back.bit_depth, back.max_dn),
            (table.bit_depth, table.max_dn)
        );
        for v in [-0.5, 0.25, 1.0, 3.0] {
            assert_eq!(back.intensity(v), table.intensity(v));
        }

        let field = |m: v1::ResponseCurve| response_from_message(&m).unwrap_err().field;
        assert_eq!(
            field(v1::ResponseCurve {
                bit_depth: 4,
                ..msg.clone()
            }),
            "bit_depth"
        );
        assert_eq!(
            field(v1::ResponseCurve {
                max_dn: 7,
                ..msg.clone()
            }),
            "max_dn"
        );
        let mut m = msg.clone();
        m.inverse_ln_exposure.pop();
        assert_eq!(field(m), "inverse_ln_exposure");
        let mut m = msg.clone();
        m.inverse_dn[3] = f64::NAN;
        assert_eq!(field(m), "inverse_dn");
        let mut m = msg.clone();
        m.forward_intensity.pop();
        assert_eq!(field(m), "forward_intensity");
        let mut m = msg.clone();
        m.forward_ln_exposure[5] += 1.0;
        assert_eq!(field(m), "forward_ln_exposure");
        let mut m = msg;
        m.forward_intensity[0] = 1.5;
        assert_eq!(field(m), "forward_intensity");
    }
}
