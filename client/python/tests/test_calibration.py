"""The calibration service from Python with default gRPC limits: a synthetic exposure stack
streamed in chunks gives back the camera response, and bad input is INVALID_ARGUMENT naming the
field."""

import math

import grpc
import pytest

CHUNK = 1 << 20
WIDTH, HEIGHT, BITS = 64, 48, 8
EXPOSURES_S = [0.001, 0.002, 0.004, 0.008, 0.016]


def true_dn(radiance, dt):
    """A gamma-like response: DN = 255 * min(1, (E dt / 0.02) ** 0.6)."""
    return round(255 * min(1.0, (radiance * dt / 0.02) ** 0.6))


def stack_images():
    """Radiances spread log-uniformly over 3 decades across the image."""
    images = []
    for dt in EXPOSURES_S:
        data = bytearray()
        for v in range(HEIGHT):
            for u in range(WIDTH):
                radiance = 10 ** (-1 + 3 * (v * WIDTH + u) / (WIDTH * HEIGHT - 1))
                data.append(true_dn(radiance, dt))
        images.append(bytes(data))
    return images


def stream(pb, common, images, bit_depth=BITS):
    arrays = [
        common.ArrayHeader(
            name=f"exposure_{i:03}",
            image=common.Image(
                width_px=WIDTH,
                height_px=HEIGHT,
                encoding=common.IMAGE_ENCODING_MONO8,
                pixel_space=common.PIXEL_SPACE_CAMERA_RESPONSE,
            ),
            size_bytes=len(data),
        )
        for i, data in enumerate(images)
    ]
    yield pb.ExposureStackChunk(
        header=pb.ExposureStackHeader(exposures_s=EXPOSURES_S, arrays=arrays, bit_depth=bit_depth)
    )
    for index, data in enumerate(images):
        for offset in range(0, len(data), CHUNK):
            yield pb.ExposureStackChunk(
                chunk=common.BytesChunk(array=index, offset=offset, data=data[offset : offset + CHUNK])
            )


def test_calibrate_response_recovers_the_curve(stubs, calibration_server):
    pb, pb_grpc, common = stubs
    with grpc.insecure_channel(calibration_server) as channel:
        client = pb_grpc.CalibrationServiceStub(channel)
        reply = client.CalibrateResponse(stream(pb, common, stack_images()), timeout=60)
    curve = reply.response
    assert curve.bit_depth == BITS and curve.max_dn == 255
    assert len(curve.inverse_dn) == len(curve.inverse_ln_exposure) == 256
    # g^-1 of the true response is ln X = ln(0.02) + ln(DN/255) / 0.6 up to a constant: compare
    # slopes between DN 32 and 192 (well exposed), within 10 % (quantisation of 8-bit DNs).
    ln_x = dict(zip(curve.inverse_dn, curve.inverse_ln_exposure))
    lo, hi = min(ln_x, key=lambda d: abs(d - 32)), min(ln_x, key=lambda d: abs(d - 192))
    measured = ln_x[hi] - ln_x[lo]
    expected = (math.log(hi) - math.log(lo)) / 0.6
    assert abs(measured / expected - 1) < 0.10, (measured, expected)


def test_bad_input_names_the_field(stubs, calibration_server):
    pb, pb_grpc, common = stubs
    with grpc.insecure_channel(calibration_server) as channel:
        client = pb_grpc.CalibrationServiceStub(channel)
        with pytest.raises(grpc.RpcError) as bad_depth:
            client.CalibrateResponse(stream(pb, common, stack_images(), bit_depth=0), timeout=30)
        assert bad_depth.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "header.bit_depth" in bad_depth.value.details()
        images = stack_images()
        images[2] = images[2][:-1]  # one byte short of what its header declares
        with pytest.raises(grpc.RpcError) as short:
            client.CalibrateResponse(stream(pb, common, images), timeout=30)
        assert short.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "header.arrays[2].size_bytes" in short.value.details()
