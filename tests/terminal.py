"""Helpers for tests of what a command shows on a terminal: ``vdps`` run in a child process with a
real pseudo-terminal (a given size) as its standard output and error, or with pipes."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time

VDPS = "import sys; from vdps_hil.cli.main import entry; sys.argv[0] = 'vdps'; entry()"
_ESC = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def screen_text(raw: str) -> str:
    """The text of a terminal stream without escape sequences, carriage returns as new lines."""
    return _ESC.sub("", raw).replace("\r", "\n")


def run_on_pty(*args, timeout: float = 300.0, cols: int = 100, rows: int = 30,
               stdin=subprocess.DEVNULL, env=None, code: str = VDPS) -> tuple[int, str]:
    """(exit code, everything the child wrote to its terminal) of ``vdps ARGS`` on a pty
    (``code``: the child's Python program, ``vdps`` by default)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
    p = subprocess.Popen([sys.executable, "-c", code, *map(str, args)], stdin=stdin, stdout=slave,
                         stderr=slave, close_fds=True, env=env)
    os.close(slave)
    chunks = []
    t_end = time.monotonic() + timeout
    try:
        while time.monotonic() < t_end:
            r, _, _ = select.select([master], [], [], 0.2)
            if r:
                try:
                    data = os.read(master, 65536)
                except OSError:  # the child closed the terminal
                    break
                if not data:
                    break
                chunks.append(data)
            elif p.poll() is not None:
                break
        code = p.wait(timeout=max(1.0, t_end - time.monotonic()))
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        os.close(master)
    return code, b"".join(chunks).decode("utf-8", "replace")


def run_piped(*args, timeout: float = 300.0, **kw) -> subprocess.CompletedProcess:
    """``vdps ARGS`` with pipes for standard output and error (not a terminal)."""
    return subprocess.run([sys.executable, "-c", VDPS, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, **kw)
