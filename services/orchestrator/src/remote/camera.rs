//! [`CameraStage`] over `glint.v1.CameraService`: the rig from `GetRig` (asked before every
//! session and capture, so a camera set up anew is seen), captures from `Capture` streams reassembled into the [`CapturedView`] the in-process
//! [`crate::local::MockCamera`] returns for the same scene, pose and seed.

use glint_camera::server::{DEPTH_ARRAY, NOISE_ARRAYS, left_array_name, right_array_name};
use glint_estimation::view::ViewMeasurement;
use glint_geometry::image::{DepthMap, Image};
use glint_proto::chunks::{ArrayAssembler, AssembledArray};
use glint_proto::v1;
use glint_proto::v1::camera_service_client::CameraServiceClient;
use nalgebra::Isometry3;
use tokio::runtime::Handle;

use super::{AuthChannel, Endpoint, request, stage_error, when_admitted};
use crate::stages::{CameraInfo, CameraStage, CapturedView, StageError};

/// A camera server (the mock or a real camera's) as the session's camera.
pub struct RemoteCamera {
    handle: Handle,
    endpoint: Endpoint,
    client: CameraServiceClient<AuthChannel>,
}

/// A reply the camera should not have sent (a server bug, not the caller's input).
fn bad_reply(what: impl std::fmt::Display) -> StageError {
    StageError::Internal(format!("the camera's reply: {what}"))
}

impl RemoteCamera {
    /// A camera at `endpoint`, called through `handle`'s runtime (which must outlive it).
    /// Connects lazily: nothing is sent until the first call.
    pub fn new(handle: Handle, endpoint: Endpoint) -> Result<Self, StageError> {
        let channel = {
            // The channel's worker task is spawned on the runtime.
            let _runtime = handle.enter();
            endpoint.channel()?
        };
        Ok(Self {
            handle,
            endpoint,
            client: CameraServiceClient::new(channel),
        })
    }

    /// The camera server's address, deadline and security.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// The whole call, streaming included, within the endpoint's deadline.
    fn call<T>(
        &self,
        future: impl std::future::Future<Output = Result<T, StageError>>,
    ) -> Result<T, StageError> {
        let deadline = self.endpoint.deadline;
        super::block_on(&self.handle, async move {
            tokio::time::timeout(deadline, future)
                .await
                .unwrap_or_else(|_| {
                    Err(StageError::Unavailable(format!(
                        "the camera at {} did not answer within {deadline:?}",
                        self.endpoint.uri
                    )))
                })
        })
    }

    fn fetch_info(&self) -> Result<CameraInfo, StageError> {
        let mut client = self.client.clone();
        let message = request(v1::GetRigRequest {}, self.endpoint.deadline);
        let rig = self.call(async move {
            Ok(client
                .get_rig(message)
                .await
                .map_err(|s| stage_error(&s))?
                .into_inner())
        })?;
        camera_info(&rig)
    }
}

/// What a session needs of `GetRig`'s answer.
pub fn camera_info(rig: &v1::GetRigResponse) -> Result<CameraInfo, StageError> {
    let sli = glint_uncertainty::server::rig_from_message(rig).map_err(bad_reply)?;
    let max_dn = u16::try_from(rig.max_dn)
        .ok()
        .filter(|&m| m > 0)
        .ok_or_else(|| bad_reply(format!("max_dn {} is not 1 to 65535", rig.max_dn)))?;
    if rig.shots_per_capture == 0 {
        return Err(bad_reply(
            "shots_per_capture is 0 (a camera takes at least one shot)",
        ));
    }
    Ok(CameraInfo {
        stereo: sli.stereo,
        rig: sli,
        max_dn,
        shots: rig.shots_per_capture,
        window_radius_px: rig.window_radius_px,
        exposure_s: rig.exposure_s,
        pattern_fill: rig.pattern_fill,
    })
}

/// Reads a whole capture stream: its header and every declared array, by name.
async fn read_capture(
    mut stream: tonic::Streaming<v1::CaptureChunk>,
) -> Result<(v1::CaptureHeader, Vec<(String, AssembledArray)>), StageError> {
    use v1::capture_chunk::Part;
    let next = |m: Result<Option<v1::CaptureChunk>, tonic::Status>| m.map_err(|s| stage_error(&s));
    let header = match next(stream.message().await)? {
        Some(v1::CaptureChunk {
            part: Some(Part::Header(header)),
        }) => header,
        _ => return Err(bad_reply("the stream did not start with a CaptureHeader")),
    };
    let mut assembler =
        ArrayAssembler::new(header.arrays.clone(), "header.arrays").map_err(bad_reply)?;
    while let Some(message) = next(stream.message().await)? {
        match message.part {
            Some(Part::Chunk(chunk)) => assembler.push(chunk).map_err(bad_reply)?,
            _ => {
                return Err(bad_reply(
                    "a second header, or an empty message, after the first",
                ));
            }
        }
    }
    Ok((header, assembler.finish().map_err(bad_reply)?))
}

/// The view a capture stream describes, checked against the camera's `info`.
pub fn view_from_arrays(
    t_w_c: &Isometry3<f64>,
    info: &CameraInfo,
    max_dn: u32,
    arrays: Vec<(String, AssembledArray)>,
) -> Result<ViewMeasurement, StageError> {
    let k = &info.stereo.intrinsics;
    let mut arrays: std::collections::HashMap<String, AssembledArray> =
        arrays.into_iter().collect();
    let mut take = |name: &str| arrays.remove(name);
    let sized = |name: &str, width: u32, height: u32| {
        if (width, height) == (k.width_px, k.height_px) {
            Ok(())
        } else {
            Err(StageError::FailedPrecondition(format!(
                "the camera's {name:?} is {width}x{height} px but its rig (GetRig) is {}x{} px: the scene changed during the capture; try again",
                k.width_px, k.height_px
            )))
        }
    };
    let image = |name: &str, array: Option<AssembledArray>| -> Result<Image<u16>, StageError> {
        match array {
            Some(AssembledArray::Image(msg)) => {
                let image = Image::<u16>::try_from(msg).map_err(|e| bad_reply(e.within(name)))?;
                sized(name, image.width(), image.height())?;
                Ok(image)
            }
            Some(AssembledArray::Depth(_)) => Err(bad_reply(format!("{name:?} is not an image"))),
            None => Err(bad_reply(format!("no array {name:?}"))),
        }
    };
    let shots = info.shots as usize;
    let left = (0..shots)
        .map(|i| {
            let name = left_array_name(i);
            image(&name, take(&name))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let right = (0..shots)
        .map(|i| {
            let name = right_array_name(i);
            image(&name, take(&name))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let depth = match take(DEPTH_ARRAY) {
        Some(AssembledArray::Depth(msg)) => {
            DepthMap::try_from(msg).map_err(|e| bad_reply(e.within(DEPTH_ARRAY)))?
        }
        _ => return Err(bad_reply(format!("no depth map {DEPTH_ARRAY:?}"))),
    };
    sized(DEPTH_ARRAY, depth.depth_m.width(), depth.depth_m.height())?;
    let [a, b] = NOISE_ARRAYS;
    let noise_shots = match (take(a), take(b)) {
        (None, None) => None,
        (x, y) => Some([image(a, x)?, image(b, y)?]),
    };
    if let Some(extra) = arrays.keys().next() {
        return Err(bad_reply(format!(
            "an array {extra:?} this client does not know (the camera takes {shots} shots, GetRig says)"
        )));
    }
    let max_dn = u16::try_from(max_dn)
        .ok()
        .filter(|&m| m > 0)
        .ok_or_else(|| bad_reply(format!("header.max_dn {max_dn} is not 1 to 65535")))?;
    Ok(ViewMeasurement {
        t_w_c: *t_w_c,
        stereo: info.stereo,
        depth,
        left,
        right,
        noise_shots,
        max_dn,
    })
}

impl RemoteCamera {
    fn list_views_once(&self, count: u32) -> Result<Vec<v1::Pose>, StageError> {
        let mut client = self.client.clone();
        let message = request(
            v1::ListCandidateViewsRequest {
                count,
                ..Default::default()
            },
            self.endpoint.deadline,
        );
        self.call(async move {
            Ok(client
                .list_candidate_views(message)
                .await
                .map_err(|s| stage_error(&s))?
                .into_inner()
                .t_w_c)
        })
    }

    fn capture_once(
        &self,
        t_w_c: &Isometry3<f64>,
        seed: u64,
    ) -> Result<(v1::CaptureHeader, Vec<(String, AssembledArray)>), StageError> {
        let mut client = self.client.clone();
        let message = request(
            v1::CaptureRequest {
                t_w_c: Some(v1::Pose::with_frames(t_w_c, "world", "camera")),
                seed,
                noise_shots: true,
            },
            self.endpoint.deadline,
        );
        self.call(async move {
            let stream = client
                .capture(message)
                .await
                .map_err(|s| stage_error(&s))?
                .into_inner();
            read_capture(stream).await
        })
    }
}

/// Every call waits its turn at a camera at its bound of calls ([`when_admitted`]).
impl CameraStage for RemoteCamera {
    /// `GetRig`, asked anew each time: a mock set up again at another resolution serves the
    /// next session without a restart (a capture that disagrees with the rig asked just
    /// before it fails instead of mixing them).
    fn info(&self) -> Result<CameraInfo, StageError> {
        when_admitted(self.endpoint.deadline, || self.fetch_info())
    }

    fn candidate_views(&self, count: usize) -> Result<Vec<Isometry3<f64>>, StageError> {
        let count = u32::try_from(count)
            .map_err(|_| StageError::invalid("count", format!("{count} is too many views")))?;
        let poses = when_admitted(self.endpoint.deadline, || self.list_views_once(count))?;
        poses
            .iter()
            .map(|p| Isometry3::try_from(p).map_err(bad_reply))
            .collect()
    }

    fn capture(&self, t_w_c: &Isometry3<f64>, seed: u64) -> Result<CapturedView, StageError> {
        let info = self.info()?;
        let (header, arrays) =
            when_admitted(self.endpoint.deadline, || self.capture_once(t_w_c, seed))?;
        let measurement = view_from_arrays(t_w_c, &info, header.max_dn, arrays)?;
        Ok(CapturedView {
            measurement,
            capture_ms: header.capture_ms,
        })
    }
}
