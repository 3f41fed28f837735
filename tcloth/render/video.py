"""Frames out: PNG files (a tiny zlib writer) and MP4 video (H.264 via imageio-ffmpeg).

Nothing partial is left looking complete: a video is written to ``NAME.partial.mp4`` and
a PNG folder to ``NAME.partial/``, renamed to the final name only once every frame is in.
"""
import os
import shutil
import struct
import sys
import time
import zlib

import numpy as np

from ..errors import InstabilityError, SceneError
from .mesh import export_mesh
from .render import renderer_for


def write_png(path, image):
    """Write an (H,W,3) uint8 array as an 8-bit RGB PNG."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    h, w, _ = img.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), img.reshape(h, w * 3)], 1).tobytes()

    def chunk(tag, data):
        body = tag + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(png)


class Progress:
    """A one-line progress bar with the rate and the time left on stderr (a line per 10 %
    when stderr is not a terminal)."""

    def __init__(self, total, label, enabled=True, unit="frames", rate_unit="fps"):
        self.total, self.label, self.enabled = max(total, 1), label, enabled
        self.unit, self.rate_unit = unit, rate_unit
        self.tty = sys.stderr.isatty()
        self.start = time.perf_counter()
        self._last_decile = -1

    def update(self, done):
        if not self.enabled:
            return
        frac = min(done / self.total, 1.0)
        elapsed = max(time.perf_counter() - self.start, 1e-9)
        rate = done / elapsed
        left = elapsed * (self.total - done) / done if done else float("nan")
        eta = "?" if left != left else f"{int(left) // 60}:{int(left) % 60:02d}"
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        line = (f"{self.label} [{bar}] {done}/{self.total} {self.unit}, "
                f"{rate:.1f} {self.rate_unit}, {eta} left")
        if self.tty:
            sys.stderr.write("\r" + line + ("\n" if done >= self.total else ""))
        elif int(10 * frac) != self._last_decile:
            self._last_decile = int(10 * frac)
            sys.stderr.write(line + "\n")
        sys.stderr.flush()


class _PngSink:
    def __init__(self, path):
        self.final = path
        self.tmp = path.rstrip("/") + ".partial"
        shutil.rmtree(self.tmp, ignore_errors=True)
        os.makedirs(self.tmp)
        self.count = 0

    def write(self, image):
        write_png(os.path.join(self.tmp, f"frame_{self.count:05d}.png"), image)
        self.count += 1

    def close(self):
        if os.path.isdir(self.final):
            shutil.rmtree(self.final)
        os.replace(self.tmp, self.final)

    def abort(self):
        shutil.rmtree(self.tmp, ignore_errors=True)


class _Mp4Sink:
    def __init__(self, path, width, height, fps, quality):
        import imageio_ffmpeg

        if width % 2 or height % 2:
            raise SceneError(f"MP4 (yuv420p) needs an even width and height "
                             f"(got width={width}, height={height})")
        self.final = path
        root, ext = os.path.splitext(path)
        self.tmp = root + ".partial" + ext
        self.gen = imageio_ffmpeg.write_frames(
            self.tmp, (width, height), fps=fps, codec="libx264", pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p", quality=quality, macro_block_size=2,
            output_params=["-preset", "veryfast"])
        self.gen.send(None)
        self.count = 0

    def write(self, image):
        self.gen.send(np.ascontiguousarray(image))
        self.count += 1

    def close(self):
        self.gen.close()
        os.replace(self.tmp, self.final)

    def abort(self):
        self.gen.close()
        if os.path.exists(self.tmp):
            os.remove(self.tmp)


def check_writable(path):
    """Make the output's folder and fail early (SceneError) if it cannot be written."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise SceneError(f"cannot create output folder {folder!r}: {e.strerror}") from None
    if not os.access(folder, os.W_OK):
        raise SceneError(f"output folder {folder!r} is not writable")


def record(sim, path, frames=240, steps_per_frame=10, fps=30, width=640, height=480,
           camera=None, supersample=2, quality=7, progress=True, mesh_dir=None,
           **render_options):
    """Simulate and render ``frames`` frames to ``path``.

    Args:
        path: "*.mp4" for H.264 video; anything else is a folder of PNG frames.
        frames: number of frames (the first shows the current state).
        steps_per_frame: simulator steps between frames. fps: video frame rate.
        quality: H.264 quality 0-10 (imageio-ffmpeg's scale).
        mesh_dir: also write each frame's cloth mesh there (frame_00000.obj, ...).
    Returns:
        dict: frames, path, sim_ms_per_step, render_ms_per_frame, encode_ms_per_frame, fps
        (means), and median_sim_ms, median_render_ms, median_encode_ms (per frame).
    On InstabilityError the frames up to the last good one are kept, completed under
    ``path``, and the error is raised again with the frame count added to its message.
    """
    for name, value in (("frames", frames), ("steps_per_frame", steps_per_frame)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise SceneError(f"{name} must be a positive integer (got {value!r})")
    check_writable(path)
    if mesh_dir is not None:
        check_writable(os.path.join(mesh_dir, "frame.obj"))
    renderer = renderer_for(sim, width, height, camera, supersample, **render_options)
    sink = _Mp4Sink(path, width, height, fps, quality) if path.lower().endswith(".mp4") \
        else _PngSink(path)
    bar = Progress(frames, os.path.basename(path), progress)
    t_sim, t_render, t_encode = [], [], []
    start = time.perf_counter()
    try:
        for k in range(frames):
            if k:
                t0 = time.perf_counter()
                sim.step(steps_per_frame)
                t_sim.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            image = renderer.render()
            t1 = time.perf_counter()
            sink.write(image)
            t_render.append(t1 - t0)
            t_encode.append(time.perf_counter() - t1)
            if mesh_dir is not None:
                export_mesh(sim, os.path.join(mesh_dir, f"frame_{k:05d}.obj"))
            bar.update(k + 1)
    except InstabilityError as err:
        sink.close()
        kept = f"{sink.count} good frame{'' if sink.count == 1 else 's'}"
        err.args = (f"{err.args[0]} Kept {kept} in {path}.",)
        raise
    except BaseException:
        sink.abort()
        raise
    sink.close()
    total = time.perf_counter() - start
    stats = {"frames": frames, "path": path,
             "sim_ms_per_step": 1e3 * sum(t_sim) / max((frames - 1) * steps_per_frame, 1),
             "render_ms_per_frame": 1e3 * sum(t_render) / frames,
             "encode_ms_per_frame": 1e3 * sum(t_encode) / frames,
             "fps": frames / total,
             "median_sim_ms": 1e3 * float(np.median(t_sim)) if t_sim else 0.0,
             "median_render_ms": 1e3 * float(np.median(t_render)),
             "median_encode_ms": 1e3 * float(np.median(t_encode))}
    if progress:
        sys.stderr.write(
            f"wrote {path}: {frames} frames; simulation {stats['sim_ms_per_step']:.3f} ms/step "
            f"({steps_per_frame} steps/frame), render {stats['render_ms_per_frame']:.1f} ms/frame, "
            f"encode {stats['encode_ms_per_frame']:.1f} ms/frame, {stats['fps']:.1f} frames/s "
            "end to end\n")
    return stats
