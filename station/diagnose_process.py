"""A diagnosis in a process of its own, for the TUI: it says each step as it begins, and can be
stopped at once.

A compass diagnosis takes 10 s on an idle machine and 60-90 s on a loaded one. Run in a thread
of the TUI it could not be stopped (a thread cannot be killed: Escape left it running, and a
second Diagnose ran beside it), and it shared the interpreter with the screen. Here it runs in
``python -m station.diagnose_process FD``: the capture goes in pickled on stdin, and each line
on the pipe ``FD`` is one JSON object, ``{"step": ...}`` as a step begins, then ``{"text": ...}``
(the report) or ``{"error": ...}`` (one line). Nothing is written anywhere else, so stopping it
(:meth:`DiagnosisProcess.cancel`, SIGKILL) leaves nothing half done.
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import tempfile


class DiagnosisProcess:
    """The parent's end: ``start()``, then ``messages()`` until it ends; ``cancel()`` from any thread."""

    def __init__(self, capture, width: int) -> None:
        self.capture = capture
        self.width = width
        self.proc: subprocess.Popen | None = None
        self.cancelled = False
        self._stderr = None

    def start(self) -> None:
        r, w = os.pipe()
        # the station package this process runs (a worktree, an editable install): the child's too
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
        self._stderr = tempfile.TemporaryFile()
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "station.diagnose_process", str(w)],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,  # never onto the TUI's terminal
                stderr=self._stderr,
                pass_fds=(w,),
                env=env,
                start_new_session=True,  # ctrl+c in the terminal is the TUI's, not the child's
            )
        finally:
            os.close(w)
        self._out = os.fdopen(r, "r", encoding="utf-8")
        try:
            pickle.dump((self.capture, self.width), self.proc.stdin)
            self.proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass  # it ended already: said by messages()

    def messages(self):
        """Each message of the child as a dict, as it comes; the last is ``text`` or ``error``
        (none after a cancel)."""
        done = False
        with self._out:
            for line in self._out:
                try:
                    msg = json.loads(line)
                except ValueError:
                    continue
                done = done or "text" in msg or "error" in msg
                yield msg
        code = self.proc.wait()
        if not done and not self.cancelled:
            self._stderr.seek(0)
            tail = [x for x in self._stderr.read().decode("utf-8", "replace").splitlines() if x.strip()]
            yield {
                "error": f"the diagnosis ended without a result (exit status {code})"
                + (f": {tail[-1]}" if tail else "")
            }
        self._stderr.close()

    def cancel(self) -> None:
        """Stop it now (it writes nothing but its pipe: nothing is left half done)."""
        self.cancelled = True
        if self.proc is not None and self.proc.poll() is None:
            try:
                self.proc.kill()
            except ProcessLookupError:
                pass


def _child(fd: int) -> int:
    out = os.fdopen(fd, "w", encoding="utf-8", buffering=1)

    def say(**msg) -> None:
        out.write(json.dumps(msg) + "\n")
        out.flush()

    try:
        say(step="loading the capture and the diagnosis")
        capture, width = pickle.load(sys.stdin.buffer)
        from station.procedures.diagnose import analyse, format_text

        result, diag, inp = analyse(capture, progress=lambda what: say(step=what))
        say(step="writing the report")
        say(text=format_text(result, diag, inp, plots=True, plot_width=width, width=width))
    except Exception as exc:  # noqa: BLE001 - one line on screen
        say(error=" ".join(str(exc).split()) or type(exc).__name__)
    return 0


if __name__ == "__main__":
    sys.exit(_child(int(sys.argv[1])))
