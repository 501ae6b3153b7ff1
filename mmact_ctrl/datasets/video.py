"""Camera frames as mp4 files through PyAV (h264), and read back by timestamp.

One file holds one camera's frames of many episodes, one after another, each frame's presentation time a whole
number of frames over ``fps`` (the stream's time base is ``1 / fps``, frame ``n`` of the file has ``pts = n``). An
episode's ``from_timestamp`` is then ``first_frame / fps`` computed from a frame count, never a running float sum
(LeRobot issue #3177: a float sum drifts past the decoder's 1e-4 s tolerance after about 30 episodes).

Encoding follows LeRobot's ``encode_video_frames`` where it matters for reading: a keyframe every ``gop`` frames
(2: any frame is decoded from at most one other), no B-frames; h264 instead of its default AV1 (LeRobot accepts both).
The pixel format is ``yuv444p`` by default, not LeRobot's ``yuv420p``: 4:2:0 halves the colour planes, and on our
small renders that is a floor of its own (measured on the reach scene at crf 18: min PSNR 31 dB at 32 px, 35.1 dB
at 96 px, where a ball is 4 px wide and its colour is what names it; 4:4:4 gives 37.5 and 40.2 dB for the same
bytes). ``yuv420p`` (``--pix-fmt``) plays in a web browser (the Hub's dataset viewer); both decode with PyAV,
torchcodec and ffmpeg, which LeRobot trains from.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

#: the codec name as LeRobot's ``info.json`` spells it, and the encoder PyAV uses for it
CODEC = "h264"
ENCODER = "libx264"
PIX_FMTS: tuple[str, ...] = ("yuv444p", "yuv420p")


def _av():
    try:
        import av
    except ImportError:
        raise RuntimeError("--format lerobot needs PyAV: pip install -e '.[dataset]'") from None
    return av


@dataclass(frozen=True)
class VideoSettings:
    """How a camera's frames are encoded.

    Attributes:
        fps: frames per second (the stream's time base is ``1 / fps``).
        crf: x264's constant rate factor (lower: larger files, less loss).
        gop: frames between keyframes.
    """

    fps: int
    crf: int = 18
    gop: int = 2
    preset: str = "medium"
    pix_fmt: str = "yuv444p"

    def __post_init__(self) -> None:
        if not (isinstance(self.fps, int) and self.fps > 0):
            raise ValueError(f"VideoSettings.fps must be a positive integer, got {self.fps!r}")
        if self.pix_fmt not in PIX_FMTS:
            raise ValueError(f"--pix-fmt {self.pix_fmt!r}: one of {PIX_FMTS}")

    def info(self) -> dict:
        """The encoder's part of LeRobot's video ``info`` block (its ``VideoEncoderConfig`` fields)."""
        return {"video.g": self.gop, "video.crf": self.crf, "video.preset": self.preset, "video.fast_decode": 0,
                "video.video_backend": "pyav", "video.extra_options": {"bf": 0}, "is_depth_map": False}


class VideoWriter:
    """Append ``(H, W, 3)`` uint8 frames to one mp4 file; :attr:`frames` counts them (the next frame's pts)."""

    def __init__(self, path: str | Path, height_px: int, width_px: int, settings: VideoSettings) -> None:
        if height_px % 2 or width_px % 2:
            raise ValueError(f"h264 video here needs an even frame size, got {height_px} x {width_px} px")
        av = _av()
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.settings = settings
        self._container = av.open(str(self.path), mode="w")
        stream = self._container.add_stream(ENCODER, rate=settings.fps)
        stream.width, stream.height = int(width_px), int(height_px)
        stream.pix_fmt = settings.pix_fmt
        stream.time_base = Fraction(1, settings.fps)
        stream.codec_context.time_base = Fraction(1, settings.fps)
        stream.options = {"crf": str(settings.crf), "g": str(settings.gop), "bf": "0", "preset": settings.preset}
        self._stream = stream
        self._av = av
        self.frames = 0
        self.shape = (int(height_px), int(width_px), 3)

    def append(self, frame: np.ndarray) -> None:
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        if frame.shape != self.shape:
            raise ValueError(f"{self.path.name}: frame of shape {frame.shape}, the file holds {self.shape}")
        vf = self._av.VideoFrame.from_ndarray(frame, format="rgb24")
        vf.pts = self.frames
        vf.time_base = Fraction(1, self.settings.fps)
        for packet in self._stream.encode(vf):
            self._container.mux(packet)
        self.frames += 1

    def close(self) -> None:
        if self._container is None:
            return
        for packet in self._stream.encode():
            self._container.mux(packet)
        self._container.close()
        self._container = None


def read_frames(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Every frame of ``path``: ``(timestamps_s (N,), frames (N, H, W, 3) uint8)`` in presentation order, each
    timestamp ``pts * time_base`` as the container says it."""
    av = _av()
    times, frames = [], []
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        for frame in container.decode(stream):
            times.append(float(frame.pts * frame.time_base))
            frames.append(frame.to_ndarray(format="rgb24"))
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], np.stack(frames)[order] if frames else np.zeros((0, 0, 0, 3), np.uint8)


def stream_info(path: str | Path) -> dict:
    """LeRobot's ``info`` block of a video feature (``video.height``, ``video.width``, ``video.codec``,
    ``video.pix_fmt``, ``video.fps``, ``video.channels``, ``has_audio``, and v0.4's ``video.is_depth_map``), read
    from the file."""
    av = _av()
    with av.open(str(path)) as container:
        s = container.streams.video[0]
        ctx = s.codec_context
        return {"video.height": int(ctx.height), "video.width": int(ctx.width), "video.codec": CODEC,
                "video.pix_fmt": str(ctx.pix_fmt), "video.is_depth_map": False,
                "video.fps": int(round(float(s.base_rate or s.average_rate))), "video.channels": 3,
                "has_audio": bool(container.streams.audio)}


def psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    """Peak signal-to-noise ratio of two uint8 images, dB (inf when equal)."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0 ** 2 / mse)
