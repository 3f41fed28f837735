"""Frames out: PNG files (a tiny zlib writer) and MP4 video (H.264 via imageio-ffmpeg).

Nothing partial is left looking complete: a video is written to ``NAME.partial.mp4`` and
a PNG folder to ``NAME.partial/``, renamed to the final name only once every frame is in.
Frames are encoded on a thread of their own (``_Writer``), beside the simulation and the
rendering of the next ones.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Optional, Sequence

import os
import queue
import shutil
import struct
import sys
import threading
import time
import zlib

import numpy as np

from ..errors import InstabilityError, SceneError
from .mesh import export_mesh
from .render import renderer_for

if TYPE_CHECKING:
    from ..sim.simulator import Simulator


def write_png(path: str, image: np.ndarray) -> None:
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


class _Writer:
    """A sink written on a thread of its own: ``put(image)`` hands a frame over (waiting
    while ``depth`` frames wait already) and returns, the thread writes the frames in
    order and times each (``times``, s). An error of the sink's stops its writing (the
    thread takes and drops what follows, so that ``put`` never waits for ever) and is
    raised again by the next ``put`` or by ``close``. ``close`` writes every frame
    handed over, then closes the sink (aborts it after an error); ``abort`` drops those
    not yet written and aborts it."""

    def __init__(self, sink, depth=4):
        self.sink, self.times, self.error = sink, [], None
        self.frames = queue.Queue(maxsize=depth)
        self.thread = threading.Thread(target=self._run, name="tcloth frame writer",
                                       daemon=True)
        self.thread.start()

    def _run(self):
        while (image := self.frames.get()) is not None:
            if self.error is None:
                t0 = time.perf_counter()
                try:
                    self.sink.write(image)
                except BaseException as e:      # raised again on the caller's thread
                    self.error = e
                self.times.append(time.perf_counter() - t0)

    def _check(self):
        if self.error is not None:
            raise self.error

    def put(self, image):
        self._check()
        self.frames.put(image)

    def _finish(self):
        self.frames.put(None)
        self.thread.join()

    def close(self):
        self._finish()
        if self.error is not None:
            self.sink.abort()
            raise self.error
        self.sink.close()

    def abort(self):
        try:
            while True:
                self.frames.get_nowait()
        except queue.Empty:
            pass
        self._finish()
        self.sink.abort()


class _ImageSink:
    """Frames rendered and written to a video or a PNG folder (``write()`` renders the
    simulator's current state and hands it to the writer's thread), the render and encode
    times apart."""

    def __init__(self, sim, path, fps, quality, width, height, camera, supersample, options):
        self.renderer = renderer_for(sim, width, height, camera, supersample, **options)
        self.writer = _Writer(_Mp4Sink(path, width, height, fps, quality)
                              if path.lower().endswith(".mp4") else _PngSink(path))
        self.path, self.t_render = path, []

    @property
    def t_encode(self):
        return self.writer.times

    def write(self):
        t0 = time.perf_counter()
        image = self.renderer.render()
        self.t_render.append(time.perf_counter() - t0)
        self.writer.put(image)

    def close(self):
        self.writer.close()

    def abort(self):
        self.writer.abort()


class _MeshSink:
    """Each frame's cloth mesh as ``frame_<k>.obj`` in a folder."""
    label = "meshes"

    def __init__(self, sim, folder):
        check_writable(os.path.join(folder, "frame.obj"))
        self.sim, self.path, self.count = sim, folder, 0

    def write(self):
        export_mesh(self.sim, os.path.join(self.path, f"frame_{self.count:05d}.obj"))
        self.count += 1

    def close(self):
        pass

    def abort(self):
        pass


def record(sim: Simulator, path: str, frames: int = 240, steps_per_frame: int = 10, *,
           fps: float = 30, width: int = 640, height: int = 480, camera: Optional[dict] = None,
           supersample: int = 2, quality: int = 7, progress: bool = True,
           mesh_dir: Optional[str] = None, writers: Sequence = (),
           **render_options: Any) -> None:
    """Simulate and render ``frames`` frames to ``path``.

    Args:
        path: "*.mp4" for H.264 video; anything else is a folder of PNG frames; None: no
            images (the writers and mesh_dir alone).
        frames: number of frames (the first shows the current state).
        steps_per_frame: simulator steps between frames. fps: video frame rate.
        quality: H.264 quality 0-10 (imageio-ffmpeg's scale).
        mesh_dir: also write each frame's cloth mesh there (frame_00000.obj, ...).
        writers: more outputs, each written a frame at a time (``write()`` after the
            frame's steps, ``close()`` at the end, ``abort()`` on an error; ``path`` and
            ``label`` name it in messages), e.g. ``tcloth.UsdWriter``: a USD stage.
    Returns:
        dict: frames, path, sim_ms_per_step, render_ms_per_frame, encode_ms_per_frame,
        write_ms_per_frame (the writers and meshes), fps (means), and median_sim_ms,
        median_render_ms, median_encode_ms, median_write_ms (per frame).
    On InstabilityError the frames up to the last good one are kept, completed under
    ``path`` and each writer's, and the error is raised again with the frame count added
    to its message; on KeyboardInterrupt (Ctrl-C) likewise the frames made so far.
    While the simulation steps and the renderer draws, the frames before are encoded on
    a thread of its own (the summary's medians: each step, render and encode alone).
    """
    for name, value in (("frames", frames), ("steps_per_frame", steps_per_frame)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise SceneError(f"{name} must be a positive integer (got {value!r})")
    outputs = list(writers) + ([_MeshSink(sim, mesh_dir)] if mesh_dir is not None else [])
    if path is not None:
        check_writable(path)
        outputs.insert(0, _ImageSink(sim, path, fps, quality, width, height, camera,
                                     supersample, render_options))
    if not outputs:
        raise SceneError("record needs a path, mesh_dir or writers (got none of them)")
    paths = " and ".join(str(o.path) for o in outputs)
    images = outputs[0] if path is not None else None
    times = _run(sim, outputs, images, frames, steps_per_frame, paths,
                 Progress(frames, os.path.basename(str(outputs[0].path)), progress))
    stats = _stats(frames, path, steps_per_frame, times, images)
    if progress:
        done = [f"simulation {stats['median_sim_ms']:.1f} ms/frame ({steps_per_frame} "
                f"step{'s' if steps_per_frame > 1 else ''} of "
                f"{stats['median_sim_ms'] / steps_per_frame:.3f} ms)"]
        if images:
            done += [f"render {stats['median_render_ms']:.1f} ms/frame",
                     f"encode {stats['median_encode_ms']:.1f} ms/frame"]
        if len(outputs) > bool(images):
            done.append(f"{' and '.join(o.label for o in outputs if o is not images)} "
                        f"{stats['median_write_ms']:.1f} ms/frame")
        sys.stderr.write(f"wrote {paths}: {frames} frames; {', '.join(done)} (medians), "
                         f"{stats['fps']:.1f} frames/s end to end\n")
    return stats


def _run(sim, outputs, images, frames, steps_per_frame, paths, bar):
    """Step and hand every frame to each output; (total s, per-frame step s, per-frame
    output s but the images' (``images``: their output or None)). The outputs are closed
    (kept) on InstabilityError and KeyboardInterrupt, aborted on any other error."""
    t_sim, t_write = [], []
    start = time.perf_counter()
    try:
        for k in range(frames):
            if k:
                t0 = time.perf_counter()
                sim.step(steps_per_frame)
                t_sim.append(time.perf_counter() - t0)
            t_frame = 0.0
            for out in outputs:
                t0 = time.perf_counter()
                out.write()
                if out is not images:
                    t_frame += time.perf_counter() - t0
            t_write.append(t_frame)
            bar.update(k + 1)
    except (InstabilityError, KeyboardInterrupt) as err:
        _close(outputs)
        kept = f"{len(t_write)} good frame{'' if len(t_write) == 1 else 's'}"
        err.args = (f"{err.args[0] if err.args else 'Interrupted.'} Kept {kept} in {paths}.",)
        raise
    except BaseException:
        for out in outputs:
            out.abort()
        raise
    _close(outputs)
    return time.perf_counter() - start, t_sim, t_write


def _close(outputs):
    """Close every output, whichever fails; the first error raised again."""
    errors = []
    for out in outputs:
        try:
            out.close()
        except BaseException as e:
            errors.append(e)
    if errors:
        raise errors[0]


def _stats(frames, path, steps_per_frame, times, images):
    """``record``'s stats dict."""
    total, t_sim, t_write = times
    t_render = images.t_render if images else [0.0]
    t_encode = images.t_encode if images else [0.0]
    stats = {"frames": frames, "path": path,
             "sim_ms_per_step": 1e3 * sum(t_sim) / max((frames - 1) * steps_per_frame, 1),
             "render_ms_per_frame": 1e3 * sum(t_render) / frames,
             "encode_ms_per_frame": 1e3 * sum(t_encode) / frames,
             "write_ms_per_frame": 1e3 * sum(t_write) / frames,
             "fps": frames / total,
             "median_sim_ms": 1e3 * float(np.median(t_sim)) if t_sim else 0.0,
             "median_render_ms": 1e3 * float(np.median(t_render)),
             "median_encode_ms": 1e3 * float(np.median(t_encode)),
             "median_write_ms": 1e3 * float(np.median(t_write))}
    return stats
