"""Guo & Zhao's FEM x DEM files from Debian, copied into a job directory and patched (``port.patch``).

``port.patch`` is a unified diff against the installed files of Debian's ``yade`` and ``libyade``
2023.02a-1 with a header that names every file the job uses (``# file: PATH | PACKAGE VERSION |
sha256 HEX | NAME IN THE JOB``) and the link ``FEMxDEM/yadeimport.py -> /usr/bin/yade``.
:func:`install_port` copies each file, refuses a copy whose SHA-256 is not the recorded one (the
patch was made against exactly those files), applies the hunks strictly (every context and removed
line must match at the stated line: no offset, no fuzz) and writes the job's files. Any refusal is a
:class:`PortError` naming the file (and hunk).
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import ReferenceRunError

HERE = Path(__file__).resolve().parent
PATCH = HERE / "port.patch"
#: gransim's recorder, copied into every job unchanged (runs under Debian's python3)
RECORDER = HERE / "job" / "femxdem_record.py"
INSTALL_HINT = "apt-get install yade python3-escript"


class PortError(ReferenceRunError):
    """Debian's files are missing or are not the ones ``port.patch`` was made against, or a hunk
    does not apply."""


@dataclass(frozen=True)
class Original:
    """One of Debian's files: installed ``path``, ``package`` (name and version), ``sha256``, and
    ``name``, its relative path in the job directory."""

    path: str
    package: str
    sha256: str
    name: str


@dataclass(frozen=True)
class Port:
    """The parsed ``port.patch``: the originals, the links (job name -> target), the hunks per job
    file (``(old_start, old_lines, new_lines)``), and the patch's own SHA-256."""

    originals: tuple
    links: tuple
    hunks: dict
    sha256: str


_FILE = re.compile(r"^# file: (\S+) \| (.+?) \| sha256 ([0-9a-f]{64}) \| (\S+)$")
_LINK = re.compile(r"^# link: (\S+) -> (\S+) \| (.+)$")
_HUNK = re.compile(r"^@@ -(\d+)(?:,(\d+))? \+(\d+)(?:,(\d+))? @@")


def read_port(path=PATCH) -> Port:
    """Parse ``port.patch`` (header and hunks); a malformed patch is a :class:`PortError`."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise PortError(f"{path}: cannot read the port patch ({exc.strerror})") from None
    lines = raw.decode().splitlines()
    originals, links, hunks = [], [], {}
    target = None
    i = 0
    while i < len(lines):
        line = lines[i]
        if m := _FILE.match(line):
            originals.append(Original(m.group(1), m.group(2), m.group(3), m.group(4)))
        elif m := _LINK.match(line):
            links.append((m.group(1), m.group(2)))
        elif line.startswith("--- "):
            if i + 1 >= len(lines) or not lines[i + 1].startswith("+++ "):
                raise PortError(f"{path}:{i + 1}: '---' without its '+++' line")
            src, target = line[4:].strip(), lines[i + 1][4:].strip()
            known = {o.name: o for o in originals}
            if target not in known or known[target].path != src:
                raise PortError(f"{path}:{i + 1}: {src} -> {target} is not a file of the header")
            hunks[target] = []
            i += 1
        elif m := _HUNK.match(line):
            if target is None:
                raise PortError(f"{path}:{i + 1}: a hunk before any file header")
            n_old = 1 if m.group(2) is None else int(m.group(2))
            n_new = 1 if m.group(4) is None else int(m.group(4))
            old, new = [], []
            j = i + 1
            while j < len(lines) and (len(old) < n_old or len(new) < n_new):
                body = lines[j]
                tag, text = body[:1], body[1:]
                if tag == " ":
                    old.append(text)
                    new.append(text)
                elif tag == "-":
                    old.append(text)
                elif tag == "+":
                    new.append(text)
                elif body == "\\ No newline at end of file":
                    pass
                else:
                    raise PortError(f"{path}:{j + 1}: unexpected line in a hunk of {target}")
                j += 1
            if len(old) != n_old or len(new) != n_new:
                raise PortError(f"{path}:{i + 1}: hunk of {target} cut short")
            hunks[target].append((int(m.group(1)), tuple(old), tuple(new)))
            i = j - 1
        i += 1
    if not originals:
        raise PortError(f"{path}: no '# file:' lines in the header")
    return Port(tuple(originals), tuple(links), hunks, hashlib.sha256(raw).hexdigest())


def apply_hunks(text: str, hunks, name: str) -> str:
    """``text`` with ``hunks`` applied exactly (no offset, no fuzz); :class:`PortError` naming
    ``name`` and the hunk when a context or removed line differs."""
    old_lines = text.split("\n")
    trailing = old_lines[-1] == ""
    if trailing:
        old_lines = old_lines[:-1]
    out, pos = [], 0  # pos: index of the next original line not yet copied
    for k, (start, old, new) in enumerate(hunks, 1):
        first = start - 1 if old else start
        if first < pos or first + len(old) > len(old_lines):
            raise PortError(f"{name}: hunk {k} (line {start}) lies outside the file or overlaps the previous one")
        have = tuple(old_lines[first : first + len(old)])
        if have != old:
            bad = next(n for n, (a, b) in enumerate(zip(have, old)) if a != b)
            raise PortError(
                f"{name}: hunk {k} does not apply at line {first + bad + 1}: the file has {have[bad]!r}, "
                f"the patch expects {old[bad]!r}"
            )
        out += old_lines[pos:first]
        out += list(new)
        pos = first + len(old)
    out += old_lines[pos:]
    return "\n".join(out) + ("\n" if trailing else "")


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def check_originals(port: Port | None = None) -> Port:
    """Check that every original is installed and is the file the patch was made against."""
    port = port or read_port()
    for o in port.originals:
        if not os.path.isfile(o.path):
            raise PortError(f"{o.path} (package {o.package}) is not installed: {INSTALL_HINT}")
        got = _sha256(o.path)
        if got != o.sha256:
            raise PortError(
                f"{o.path}: SHA-256 {got} is not {o.sha256}, the file of {o.package} that "
                f"{PATCH.name} was made against; the port must be redone for this version"
            )
    for _name, target in port.links:
        if not os.path.isfile(target):
            raise PortError(f"{target} is not installed: {INSTALL_HINT}")
    return port


def recorder_sha256() -> str:
    """SHA-256 of gransim's recorder (``job/femxdem_record.py``) as copied into the jobs."""
    return _sha256(RECORDER)


def install_port(job_dir, port: Port | None = None) -> Port:
    """Write the ported files, the ``yadeimport.py`` link and gransim's recorder into ``job_dir``."""
    port = check_originals(port)
    job_dir = Path(job_dir)
    for o in port.originals:
        text = Path(o.path).read_text()
        text = apply_hunks(text, port.hunks.get(o.name, ()), o.name)
        dest = job_dir / o.name
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(text)
    for name, target in port.links:
        dest = job_dir / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        if dest.is_symlink() or dest.exists():
            dest.unlink()
        dest.symlink_to(target)
    (job_dir / RECORDER.name).write_bytes(RECORDER.read_bytes())
    return port


__all__ = [
    "PATCH",
    "RECORDER",
    "Original",
    "Port",
    "PortError",
    "apply_hunks",
    "check_originals",
    "install_port",
    "read_port",
    "recorder_sha256",
]
