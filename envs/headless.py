"""Headless rendering of MuJoCo: a GL backend chosen only when frames are asked for.

MuJoCo picks its GL backend from ``MUJOCO_GL`` when it is first imported, and under
``MUJOCO_GL=egl`` on a machine without libEGL even ``import mujoco`` fails.
Training never renders, so nothing here runs for it and ``MUJOCO_GL`` stays as the user left it.
When frames are wanted (``--video``, ``--render``) and the user set no backend and there is no
display, the first one whose library loads is chosen: EGL, then OSMesa. If none loads, rendering a
MuJoCo environment is refused in one line that says what to install.
"""

from __future__ import annotations

import ctypes
import os
import sys

import gymnasium as gym

# backend -> the shared libraries it loads (PyOpenGL's names on Linux)
GL_LIBRARIES = {"egl": ("libEGL.so.1", "libEGL.so"), "osmesa": ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")}
INSTALL_HINT = ("install EGL or OSMesa (Debian/Ubuntu: apt-get install libegl1, or libosmesa6), or run with a "
                "display and MUJOCO_GL=glfw (e.g. under xvfb-run)")


MUJOCO_RENDERERS = ("glfw", "egl", "osmesa")  # the MUJOCO_GL values gymnasium's MujocoRenderer accepts


class RenderingUnavailable(ValueError):
    """Frames were asked for but no GL backend can make them here."""


def loads(names: tuple[str, ...]) -> bool:
    for name in names:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


def choose_mujoco_gl(environ=os.environ) -> str | None:
    """For rendering: the user's ``MUJOCO_GL``, else (without a display) the first backend that loads,
    which is then set for MuJoCo to find; None where nothing was set and none loads."""
    if environ.get("MUJOCO_GL") or environ.get("DISPLAY"):
        return environ.get("MUJOCO_GL")
    for backend, names in GL_LIBRARIES.items():
        if loads(names):
            environ["MUJOCO_GL"] = backend
            return backend
    return None


def is_mujoco(env: gym.Env) -> bool:
    if "mujoco" not in sys.modules:  # made no MuJoCo environment, so this is none
        return False
    from gymnasium.envs.mujoco import MujocoEnv

    return isinstance(env.unwrapped, MujocoEnv)


NO_DISPLAY = ("--render shows a window, and there is no display (DISPLAY is not set); use --video PATH to record "
              "the episode instead, or run under xvfb-run for a virtual display")


def check_display(render_mode: str | None, environ=os.environ, platform: str = sys.platform) -> None:
    """Refuse a window on a Linux machine without a display, before any environment is made, whatever the
    drivers say: MuJoCo's window aborts the process (SIGABRT) under SDL_VIDEODRIVER=dummy or a MUJOCO_GL
    without a display, pyBullet's GUI waits for an X server forever, and pygame's dummy driver shows nothing."""
    if render_mode == "human" and platform.startswith("linux") and not (
            environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY")):
        raise RenderingUnavailable(NO_DISPLAY)


def check_can_render(envs: list[gym.Env], render_mode: str | None, environ=os.environ) -> None:
    """Refuse, before any episode runs, frames that an environment cannot make, or that no backend here
    can render."""
    if render_mode is None:
        return
    for env in envs:
        modes = env.metadata.get("render_modes") or ()
        if render_mode not in modes:
            raise RenderingUnavailable(f"{env.spec.id if env.spec else type(env.unwrapped).__name__} cannot render "
                                       f"{render_mode!r} frames (its render modes: {', '.join(modes) or 'none'})")
    if not any(is_mujoco(env) for env in envs):
        return
    if render_mode == "human" and not environ.get("DISPLAY"):
        raise RenderingUnavailable(NO_DISPLAY)
    backend = environ.get("MUJOCO_GL")
    if backend and backend not in MUJOCO_RENDERERS:  # MuJoCo itself takes more (glx, cgl, wgl, disable)
        raise RenderingUnavailable(f"MUJOCO_GL={backend}: Gymnasium renders MuJoCo only with "
                                   f"{', '.join(MUJOCO_RENDERERS)}; unset MUJOCO_GL or give one of them")
    if render_mode == "rgb_array" and not environ.get("DISPLAY") and backend in (None, "", "glfw"):
        raise RenderingUnavailable(f"cannot render MuJoCo without a display: neither EGL nor OSMesa loads here; "
                                   f"{INSTALL_HINT}")


def explain_gl_failure(error: Exception, environ=os.environ) -> RenderingUnavailable | None:
    """The one-line reason for an import of MuJoCo that failed because the GL backend the user chose
    with ``MUJOCO_GL`` cannot load (``import mujoco`` loads it, even where nothing renders)."""
    backend = environ.get("MUJOCO_GL")
    chain, cause = [], error
    while cause is not None and len(chain) < 5:  # gymnasium re-raises MuJoCo's import error as its own
        chain.append(f"{type(cause).__name__}: {cause}")
        cause = cause.__cause__ or cause.__context__
    text = chain[-1] if chain else ""
    if backend and any(("NoneType" in item and "gl" in item.lower()) or "OpenGL" in item or "GLFW" in item
                       or "PYOPENGL" in item for item in chain):
        return RenderingUnavailable(f"MUJOCO_GL={backend}: its library does not load here ({text}); without "
                                    f"--video or --render nothing renders, so unset MUJOCO_GL; to render, "
                                    f"{INSTALL_HINT}")
    return None
