"""``--logger wandb``: the run in Weights & Biases (``requirements-wandb.txt``).

The W&B run's config is the run's config.json; each metrics row is one ``run.log`` at its generation;
the figures and final weight files are two artifacts, ``figures-<id>`` and ``weights-<id>``. The W&B
run's id is made here and recorded in config.json (``log.wandb_run_id``), so that a resumed run
continues the same W&B run (``resume="allow"``); the generations it already holds are not sent again.

Online or offline: ``WANDB_MODE`` when it is set; otherwise online where a login is configured
(``WANDB_API_KEY``, or the key ``wandb login`` wrote to ~/.netrc for ``WANDB_BASE_URL``'s host), and
offline where none is, the files under ``<run folder>/wandb``, to upload later with ``wandb sync``
(each process of a resumed run writes its own offline folder, all of the same run id). W&B's own
console output, code saving and system statistics are off: the run's output stays the project's.

An online run whose server nothing answers at (``WANDB_BASE_URL``'s host) stops the run's start within
``REACH_SECONDS``, in one line naming it; W&B itself would wait ``init_timeout`` (90 s). A ``WANDB_MODE``
that W&B has no such mode for is refused, naming the modes.
"""

from __future__ import annotations

import netrc
import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse

from report.loggers.base import GROUP, LoggerPlugin, unreachable
from settings import setting

DEFAULT_HOST = "https://api.wandb.ai"
MODES = ("online", "offline", "disabled", "shared", "dryrun", "run")  # WANDB_MODE's values (wandb.Settings.mode)
ONLINE = ("online", "shared", "run")  # those that reach the server


@dataclass(frozen=True)
class WandbSettings:
    wandb_project: str = setting("hebbian-es", nonempty=True, resumable=True, group=GROUP,
                                 metavar="NAME", help="the W&B project of the run")
    wandb_run_id: str | None = setting(None, flag=None, derived=True,
                                       help="the W&B run's id, made at the run's start (a resume continues it)")


def logged_in() -> bool:
    """Whether W&B has a login to use: an API key or identity token in the environment, or one in ~/.netrc."""
    if os.environ.get("WANDB_API_KEY") or os.environ.get("WANDB_IDENTITY_TOKEN_FILE"):
        return True
    host = urlparse(os.environ.get("WANDB_BASE_URL", DEFAULT_HOST)).hostname
    try:
        return netrc.netrc(os.environ.get("NETRC")).authenticators(host) is not None
    except (OSError, netrc.NetrcParseError):  # no ~/.netrc, or one W&B could not read either
        return False


def check_mode(mode: str) -> None:
    """Refuse a ``WANDB_MODE`` W&B has no such mode for, and an online run whose server nothing answers at."""
    if mode not in MODES:
        raise ValueError(f"WANDB_MODE={mode}: W&B has no such mode; give one of {', '.join(MODES[:3])} (or leave "
                         "WANDB_MODE unset: online with a login, else offline)")
    if mode not in ONLINE:
        return
    base = os.environ.get("WANDB_BASE_URL", DEFAULT_HOST)
    reason = unreachable(base, 443 if urlparse(base).scheme == "https" else 80)
    if reason is not None:
        raise ValueError(f"the W&B server {base} (WANDB_BASE_URL) does not answer ({reason}); log offline with "
                         "WANDB_MODE=offline, or give the address of a server that runs")


class WandbLogger:
    def __init__(self, settings: WandbSettings, run_folder: Path, say=print):
        self.settings, self.folder, self.say = settings, Path(run_folder), say
        self.run = None
        self.first_step = 0  # W&B drops steps below the current one: those it holds are not sent again

    def begin(self, record: dict, generation: int) -> dict:
        import wandb

        run_id = self.settings.wandb_run_id or secrets.token_hex(4)
        mode = None if "WANDB_MODE" in os.environ else "online" if logged_in() else "offline"
        check_mode(mode or os.environ["WANDB_MODE"])
        self.run = wandb.init(project=self.settings.wandb_project, id=run_id, resume="allow", dir=str(self.folder),
                              name=self.folder.name, mode=mode,
                              settings=wandb.Settings(silent=True, console="off", save_code=False,
                                                      x_disable_stats=True))
        self.run.config.update(record, allow_val_change=True)
        self.first_step = self.run.step
        if self.run.offline:
            self.say(f"W&B: no login configured, so the run is logged offline in {self.folder / 'wandb'}; upload it "
                     f"with: wandb sync {self.folder / 'wandb'}/offline-run-*-{run_id}")
        return {"wandb_run_id": run_id}

    def log(self, step: int, values: dict[str, float]) -> None:
        if step >= self.first_step:
            self.run.log(values, step=step)

    def flush(self) -> None:
        pass

    def artefacts(self, figures: list[Path], weights: list[Path]) -> None:
        import wandb

        for kind, paths in (("figures", figures), ("weights", weights)):
            if paths:
                artifact = wandb.Artifact(f"{kind}-{self.run.id}", type=kind)
                for path in paths:
                    artifact.add_file(str(path), policy="immutable")  # read where it is, not copied
                self.run.log_artifact(artifact)

    def close(self, finished: bool) -> None:
        if self.run is not None:
            self.run.finish(exit_code=0 if finished else 1)


PLUGIN = LoggerPlugin("wandb", about="Weights & Biases, offline where no login is configured", settings=WandbSettings,
                      make=WandbLogger, modules=("wandb",), extra="wandb")
