"""The paper's campaign: a long training run done in chunks, one per session, on whatever machine is at hand.

``experiments/paper.py EXPERIMENT KIND --budget MINUTES`` runs one chunk through ``run_chunk``: the
training script (a new run, or the resume of the folder's run) as a child process, stopped at a
generation boundary before the budget is spent, everything saved. Between chunks the run folder holds
only what continuing and evaluating need (``prune``), so that it can be committed as it is and a fresh
clone on another machine continues it bit for bit (docs/experiments.md, "The campaign").

- **The budget.** Every generation appends a row to the run's metrics.csv, with its duration. When a
  row appears, the next generation has just started; if it and one more would not both end before the
  deadline, the child is asked to stop after it (SIGINT: finish the generation, save, stop). If the
  deadline comes anyway (a generation longer than the last), the child is stopped at once (a second
  SIGINT): the generation in progress is lost, the last one saved stays intact.
- **Interrupts.** SIGINT or SIGTERM to this process is passed on as a first SIGINT; if the child has not
  ended within ``GRACE`` seconds, or at a second signal, it is stopped at once. So the campaign is
  saved and gone within a minute of one SIGINT.
- **The pid file.** While a chunk runs, ``results/paper/campaign.pid`` holds this process's id (what a job
  scheduler or a shutdown script can signal to stop it cleanly); it is removed when the chunk ends. A live
  campaign's file is never taken over: a second campaign is refused, with the command that stops the first. The file is
  data (``holder``): one naming a process that has ended is taken over, and one this tool did not
  write (not a process id, or the id of a live process that is not a campaign: pid 1, an id reused)
  is refused with how to remove it; the tool never advises signalling a process that is not a campaign.
"""

from __future__ import annotations

import contextlib
import csv
import os
import shlex
import signal
import statistics
import subprocess
import time
from pathlib import Path

from report.stats import EVALUATIONS

PID_FILE = "campaign.pid"  # beside the experiments' folders: results/paper/campaign.pid
STOPPED = (130, -signal.SIGINT)  # a child that stopped at a SIGINT, its last saved generation intact
PROGRESS = "progress.md"  # beside them too: how far each run of the campaign got, written at every chunk's end
MIN_BUDGET = 1  # minutes: the least a chunk is given (the training starts, runs a generation, saves)
GRACE = 30.0  # seconds a generation may take to finish after the first SIGINT, before a stop at once
POLL = 0.5  # seconds between looks at the child and at metrics.csv
SAFETY = 1.15  # a generation may take this much longer than the last ones did
PACE_ROWS = 5  # the generations whose median duration is a generation's expected one
EVALUATION = EVALUATIONS["evaluation"]  # the final centre's evaluation: the run's result
BEST_EVALUATION = EVALUATIONS["evaluation_best"]  # the best centre's (the checkpoint keeps it), beside it
MADE_WITH = "made_with.json"  # a run made by older code: the commit and the CPUs whose generations it reproduces
# what a run folder keeps between chunks: what continuing needs, what evaluating wrote, and its label
KEPT = ("config.json", "checkpoint.npz", "metrics.csv", EVALUATION, BEST_EVALUATION, "adaptation.png", "frames.png",
        MADE_WITH)
FINAL_WEIGHTS = "last*.dat"  # kept once training is complete: the weights evaluated and shipped


class CampaignError(ValueError):
    """A campaign cannot start (another one runs)."""


@contextlib.contextmanager
def pid_file(path: Path):
    """Hold ``path`` with this process's id while the block runs; refuse one that a live campaign holds, and one
    this tool did not write (``holder``). A file naming a process that has ended is taken over, and said so."""
    pid = holder(path)
    if pid is not None and pid != os.getpid():
        print(f"campaign: {path} named process {pid}, which has ended (a campaign stopped without removing it); "
              "taking it over", flush=True)
    made = [folder for folder in (path.parent, *path.parent.parents) if not folder.exists()]
    staged = path.with_name(path.name + ".tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        staged.write_text(f"{os.getpid()}\n")
        staged.replace(path)
    except OSError as error:
        raise CampaignError(f"cannot write {path}: {error.strerror or error}") from None
    try:
        yield
    finally:
        with contextlib.suppress(OSError, ValueError):
            if int(path.read_text().strip()) == os.getpid():
                path.unlink()
        for folder in made:  # innermost first: where nothing else was written meanwhile
            try:
                folder.rmdir()
            except OSError:
                break


def holder(path: Path) -> int | None:
    """The process a pid file names, if it has ended (None: no file); a CampaignError for a live campaign's file,
    naming how to stop it, and for a file this tool did not write (not a number in the range of process ids, or
    the id of a live process that is not a campaign), naming how to remove it. The file is data: its number is
    never signalled nor advised to be unless it is a campaign's."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as error:  # a folder, a file it cannot read
        problem = "is a folder" if path.is_dir() else f"cannot be read ({getattr(error, 'strerror', None) or error})"
        raise CampaignError(f"{path} {problem}, not the campaign's pid file; move it away, then start again") \
            from None
    remove = f"if no campaign is running, remove it (rm {shlex.quote(str(path))}), then start again"
    words = text.split()
    if len(words) != 1 or not words[0].isdigit() or not 1 <= int(words[0]) <= max_pid():
        shown = f"holds {text.strip()[:40]!r}" if text.strip() else "is empty"
        raise CampaignError(f"{path} {shown}, not the id of a process this tool started; {remove}")
    pid = int(words[0])
    if pid == os.getpid() or not alive(pid):
        return pid
    running = command_line(pid)
    if running is None:  # a system without /proc: what it runs cannot be read
        raise CampaignError(f"{path} names process {pid}, which is running; if it is a campaign, wait for it to end; "
                            f"if not, {remove}")
    if not any(Path(word).name == "paper.py" for word in running):
        shown = shlex.join(running)[:80] or "no command: a kernel thread, or a process that has ended"
        raise CampaignError(f"{path} names process {pid}, which is not a campaign ({shown}): the file is left from "
                            f"a campaign that ended; {remove}")
    raise CampaignError(f"a campaign is already running (pid {pid}, in {path}); wait for it to end, or stop it with: "
                        f"kill -INT {pid}")


def max_pid() -> int:
    """The largest process id this system gives (Linux's pid_max; elsewhere a 32-bit system's)."""
    try:
        return int(Path("/proc/sys/kernel/pid_max").read_text())
    except (OSError, ValueError):
        return 2**31 - 1


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def command_line(pid: int) -> list[str] | None:
    """The words of the command process ``pid`` runs (none for a kernel thread or a process that has ended), or
    None where this system does not say (no /proc)."""
    try:
        words = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return [] if Path("/proc/self").exists() else None
    return [word.decode(errors="replace") for word in words if word]


def _last_rows(metrics: Path, count: int = 1) -> list[dict]:
    """The last ``count`` complete rows of a metrics.csv, oldest first; none where there is no file or no row yet
    (a row being written is not complete)."""
    try:
        with open(metrics, newline="") as handle:
            rows = list(csv.DictReader(handle))
    except OSError:
        return []
    complete = [row for row in rows if row.get("seconds") not in (None, "") and row.get("generation") not in (None, "")]
    return complete[-count:]


def share_niceness(pid: int) -> None:
    """Give the session of process ``pid`` this process's niceness as a whole (Linux's autogroups).

    The child runs in a session of its own, and where the kernel groups CPU time by session
    (``/proc/sys/kernel/sched_autogroup_enabled``), a new session is a new group with niceness 0, shared
    fairly with every other session: a campaign started under ``nice -n 19`` would then take half of a
    machine's CPU from a test suite or a benchmark in another session, its own niceness ranking it only
    within its group. Writing the niceness into ``/proc/PID/autogroup`` ranks the whole group, its
    workers included. Elsewhere (no autogroups, another system) nothing is done.
    """
    with contextlib.suppress(OSError):
        Path(f"/proc/{pid}/autogroup").write_text(f"{os.nice(0)}\n")


class Chunk:
    """One chunk of training: ``command`` as a child, under ``deadline`` (``time.monotonic()``), with
    ``find_metrics()`` giving the run's metrics.csv once the run folder exists."""

    def __init__(self, command: list[str], deadline: float, find_metrics, cwd: Path, log=print):
        self.command, self.deadline, self.find_metrics, self.cwd, self.log = command, deadline, find_metrics, cwd, log
        self.signals = 0  # SIGINT or SIGTERM received by this process
        self.signalled: float | None = None  # when the first one came
        self.asked = False  # the child was asked to finish its generation and stop
        self.stopped_at_once = False
        self.pending = False  # a second SIGINT to send at the next poll

    def last_generation(self) -> tuple[str | None, float | None]:
        """The last generation metrics.csv records, and how long a generation takes: the median duration, in
        seconds, of the last ``PACE_ROWS`` (one generation slowed by a loaded machine does not set the pace)."""
        metrics = self.find_metrics()
        rows = _last_rows(metrics, PACE_ROWS) if metrics is not None else []
        if not rows:
            return None, None
        return rows[-1]["generation"], statistics.median(float(row["seconds"]) for row in rows)

    def run(self) -> int:
        """The child's exit code: 0, complete; 130 (or -2: SIGINT reached it while it was closing), stopped with
        its last generation saved; anything else, it failed."""
        previous = {signum: signal.signal(signum, self._signal) for signum in (signal.SIGINT, signal.SIGTERM)}
        try:
            seen, duration = self.last_generation()  # a resumed run's: its next generation starts with the child
            saved = seen  # the last generation saved before this chunk
            began = time.monotonic()
            self.child = subprocess.Popen(self.command, cwd=self.cwd, start_new_session=True)  # only we signal it
            share_niceness(self.child.pid)
            while self.child.poll() is None:
                # asked only once the child is training (a generation of this chunk saved): a signal while it
                # starts would stop it before its first generation, and no chunk would ever make progress
                if (not self.asked and duration is not None and seen != saved
                        and began + 2 * SAFETY * duration > self.deadline):
                    self._ask("the budget leaves no room for another generation after this one")
                time.sleep(POLL)
                generation, seconds = self.last_generation()
                if generation != seen:  # a generation ended, and the next one starts
                    seen, duration, began = generation, seconds, time.monotonic()
                self._enforce(time.monotonic())
            return self.child.wait()
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)

    def _enforce(self, now: float) -> None:
        """Ask the child to stop after its generation at the first signal; stop it at once at the second, when
        it takes longer than ``GRACE`` after the first, or past the deadline (with ``GRACE`` more once
        asked: it is finishing a generation that was expected to end in time)."""
        if self.pending:  # the second of two SIGINTs, one poll after the first: two at once may count as one
            self.pending = False
            self._send()
            return
        if self.signals and not self.asked:
            self._ask("interrupted")
        late = self.signalled is not None and now - self.signalled > GRACE
        overdue = now > self.deadline + (GRACE if self.asked else 0.0)
        if not self.stopped_at_once and (self.signals >= 2 or late or overdue):
            self.stopped_at_once = True
            self.log("campaign: stopping the training at once; its last saved generation stays as it is")
            if not self.asked:
                self.asked, self.pending = True, True
            self._send()

    def _ask(self, why: str) -> None:
        self.asked = True
        self.log(f"campaign: {why}: the training finishes its generation, saves and stops")
        self._send()

    def _send(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            self.child.send_signal(signal.SIGINT)

    def _signal(self, signum, frame) -> None:
        self.signals += 1
        if self.signalled is None:
            self.signalled = time.monotonic()


def prune(run_dir: Path, complete: bool) -> list[str]:
    """Remove from ``run_dir`` what neither continuing nor evaluating needs (the per-generation copies of
    the weights, best*, the fitness log and plot, the lock); the final weights stay once ``complete``.
    Returns the names removed."""
    keep = set(KEPT) | ({path.name for path in run_dir.glob(FINAL_WEIGHTS)} if complete else set())
    removed = []
    for path in sorted(run_dir.iterdir()):
        if path.is_file() and path.name not in keep:
            path.unlink()
            removed.append(path.name)
    return removed
