//! The calibration stage's gRPC server (`glint.v1.CalibrationService`): decode and validate the
//! request, run the library on the blocking pool, encode. Errors map to codes: bad input →
//! INVALID_ARGUMENT naming the field; a stack with too few well-exposed pixels →
//! FAILED_PRECONDITION.

use std::pin::Pin;

use glint_geometry::image::Image;
use glint_proto::chunks::{ArrayAssembler, AssembledArray};
use glint_proto::v1;
use glint_proto::v1::calibration_service_server::{CalibrationService, CalibrationServiceServer};
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

use crate::response::{DebevecConfig, ExposureStack, ResponseError, ResponseTable, calibrate};

/// The service's name, as health reports it.
pub const SERVICE_NAME: &str = "glint.v1.CalibrationService";

/// The calibration service; stateless.
#[derive(Clone, Debug, Default)]
pub struct Calibration;

impl Calibration {
    /// The tonic service to add to a server's routes.
    pub fn into_service(self) -> CalibrationServiceServer<Self> {
        CalibrationServiceServer::new(self)
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
impl CalibrationService for Calibration {
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
        _request: Request<v1::FitBsdfRequest>,
    ) -> Result<Response<Self::FitBsdfStream>, Status> {
        // The fit's set-up (measured radiance per view, the reference surface's scale) still
        // lives in the CLI; it moves into this crate before it is served.
        Err(Status::unimplemented(
            "FitBsdf is not served yet: run `glint calibrate bsdf` on the capture",
        ))
    }
}
