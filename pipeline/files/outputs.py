"""Guards around the files rss6 writes: output paths checked before any work, one writer per
output (a lock file beside it), and a manifest that vouches for every stored part of an ensemble.

Every refusal is an ``EnsembleFileError`` whose message names the file and what to do.
"""
from __future__ import annotations

import hashlib
import json
import os
import socket
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..vocabulary import UserError
from .schema import EnsembleFileError
from .writing import sigint_deferred, write_netcdf

__all__ = ["check_output_path", "answered_request", "REQUEST_ATTR", "OutputLock", "PartsManifest", "parts_dir",
           "unfinished"]


def check_output_path(path, create_dirs: bool = False) -> Path:
    """Refuse (before any work) an output whose folder is missing, not writable, or that is a folder.

    The folder is created only when ``create_dirs`` is set (the ``--parents`` option).
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise EnsembleFileError(f"{path}: is a folder; give a file name for the output")
    if not folder.exists():
        if not create_dirs:
            raise EnsembleFileError(f"{path}: folder {folder} does not exist; create it or pass "
                                    "--parents")
        folder.mkdir(parents=True)
    if not folder.is_dir():
        raise EnsembleFileError(f"{path}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise EnsembleFileError(f"{path}: folder {folder} is not writable")
    if path.exists() and not os.access(path, os.W_OK):
        raise EnsembleFileError(f"{path}: exists and is not writable")
    return path


def check_output_folder(path, create_parents: bool = False, option: str = "-o") -> Path:
    """Refuse (before any work) an output folder that is a file, sits below a file, or would be made
    in a folder that is not writable; its parent folder must exist unless ``create_parents`` (the
    ``--parents`` option). ``option``: the option that named it."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise EnsembleFileError(f"{path}: exists and is not a folder; {option} names the output folder")
    nearest = path
    while not nearest.exists():
        nearest = nearest.parent if str(nearest.parent) != str(nearest) else Path(".")
    if not nearest.is_dir():
        raise EnsembleFileError(f"{path}: {nearest} is a file, not a folder")
    if not create_parents and not path.parent.is_dir():
        raise EnsembleFileError(f"{path}: folder {path.parent} does not exist; create it or pass --parents")
    if not os.access(nearest, os.W_OK | os.X_OK):
        raise EnsembleFileError(f"{path}: folder {nearest} is not writable")
    return path


@contextmanager
def claimed_output_folder(folder: Path, command: str, request: dict, answers: tuple[str, ...] = (),
                          option: str = "-o"):
    """Record in ``folder`` the request whose outputs it holds (``rss6_COMMAND_request.json``: the
    scene's sha256 and every option that changes them, keyed by the option's name), or refuse,
    before any work, a folder (named by ``option``) holding ``command``'s outputs for another request:
    a rerun of the same request resumes or rewrites the same files, and another one overwrites no
    finished answer. A folder holding the command's ``answers`` (file name patterns) without a record
    is refused too (its record deleted, or written by an rss6 that kept none). A body that ends in an
    exception before writing anything in the folder takes the record (and a folder it made) back."""
    folder = Path(folder)
    path = folder / f"rss6_{command}_request.json"
    if path.exists():
        _refuse_another_request(folder, path, command, request, option)
        yield folder
        return
    held = sorted(p.name for pattern in answers for p in folder.glob(pattern)) if folder.is_dir() else []
    if held:
        raise EnsembleFileError(f"{folder}: holds rss6 {command}'s outputs ({', '.join(held)}) but no {path.name}, "
                                "the record of the request they answer (deleted, or never written by an older rss6); "
                                f"choose another {option}, or remove them to replace them")
    made = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    before = set(folder.iterdir())
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(request, indent=1, sort_keys=True))
    os.replace(tmp, path)
    try:
        yield folder
    except BaseException:
        if set(folder.iterdir()) == before | {path}:   # nothing written: nothing to claim
            path.unlink()
            if made:
                folder.rmdir()
        raise


def _refuse_another_request(folder: Path, path: Path, command: str, request: dict, option: str) -> None:
    """EnsembleFileError unless the record ``path`` holds ``request``, naming each option it changes."""
    try:
        held = json.loads(path.read_text())
    except (OSError, ValueError):
        raise EnsembleFileError(f"{path}: unreadable; it records which request the folder's outputs answer, "
                                f"so choose another {option}, or remove the folder to replace them") from None
    said = request_changes(held, request)
    if said:
        raise EnsembleFileError(f"{folder}: holds rss6 {command}'s outputs for another request ({said}); "
                                f"choose another {option}, or remove {folder} to replace them")


def request_changes(held: dict, request: dict) -> str:
    """Each option ``request`` changes against the ``held`` record, in words ('' for none)."""
    request = json.loads(json.dumps(request))   # as a record reads back (tuples as lists)
    changed = [key for key in request | held if request.get(key) != held.get(key)]
    return "; ".join("another scene text" if key == "scene" else
                     f"{key} {_said(held.get(key))} there, {_said(request.get(key))} now" for key in changed)


def _said(value) -> str:
    """A recorded option's value as a message names it."""
    if value is None:
        return "unset"
    if isinstance(value, list):
        import shlex
        return " ".join(shlex.quote(str(v)) for v in value) or "none"
    return str(value)


def text_identity(text: str) -> str:
    """What a request record holds of a scene's text: its sha256 (any edit is another request; an input
    file's: :func:`sha256` of its path)."""
    return hashlib.sha256(text.encode()).hexdigest()


REQUEST_ATTR = "rss6_request"   # the request a command's output file answers, JSON (:func:`answered_request`)


def answered_request(path, command: str, request: dict, create_dirs: bool = False, what: str = "") -> bool:
    """Check ``rss6 COMMAND``'s output file ``path`` before any work (:func:`check_output_path`): False when it is
    absent; True when it is an earlier file of the command (its history's last line starts ``rss6 COMMAND``) that
    records the same ``request`` (the scene's sha256 and every option that changes the answer) in its
    ``rss6_request`` attribute, so that a rerun of the same request (one interrupted after writing it, say) reuses
    it instead of being refused. Any other file, or one answering another request (each option it changes named),
    is refused (EnsembleFileError), never overwritten. ``what``: how messages name the file (default COMMAND)."""
    import netCDF4
    path = check_output_path(path, create_dirs)
    if not path.exists():
        return False
    try:
        with netCDF4.Dataset(path) as nc:
            lines, held = str(getattr(nc, "history", "")).splitlines(), getattr(nc, REQUEST_ATTR, None)
    except OSError:
        lines, held = [], None
    if not (lines and lines[-1].startswith(f"rss6 {command}")):   # the last line: its own
        raise EnsembleFileError(f"{path}: exists and is not an rss6 {what or command} file; rss6 {command} does not "
                                "overwrite it (remove it or choose another -o)")
    if held is None:
        raise EnsembleFileError(f"{path}: an rss6 {command} file that records no request (an earlier rss6 "
                                "wrote it), so it cannot show it answers this one; choose another -o, or remove it "
                                "to replace it")
    said = request_changes(json.loads(held), request)
    if said:
        raise EnsembleFileError(f"{path}: holds the answer to another rss6 {command} request ({said}); "
                                "choose another -o, or remove it to replace it")
    return True


def reuse_answer(path: Path, command: str, load, leftover: Path):
    """What ``rss6 COMMAND``'s earlier run of the same request (:func:`answered_request`) wrote to ``path``, read
    by ``load(path)``: nothing is recomputed. ``leftover`` (a checkpoint file or a folder of finished chunks that
    run left, interrupted before removing it) holds nothing more and goes, once the answer has been read."""
    import shutil
    held = load(path)   # verified before it is said to answer, and before the leftover goes
    print(f"rss6 {command}: {path} already answers this request: nothing is recomputed", file=sys.stderr)
    if leftover.is_dir():
        shutil.rmtree(leftover)
    else:
        leftover.unlink(missing_ok=True)
    return held


def check_new_output(path, command: str, create_dirs: bool = False, option: str = "-o") -> Path:
    """:func:`check_output_path`, and refuse an existing file: ``command`` (e.g. "rss6 stats") writes a
    new file and overwrites none, so a second run on the same output loses nothing; ``option``: the
    option that named it."""
    path = check_output_path(path, create_dirs)
    if path.exists():
        raise EnsembleFileError(f"{path}: exists; {command} does not overwrite a file (remove it or "
                                f"choose another {option})")
    return path


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def _running(holder: dict) -> bool:
    """Whether a lock's ``holder`` ({pid, host, since}) still runs: its process is alive on this
    host, or it is on another host (which this one cannot ask)."""
    return bool(holder) and (holder.get("host") != socket.gethostname() or _alive(holder["pid"]))


def _who(holder: dict) -> str:
    where = "" if holder.get("host") == socket.gethostname() else f" on host {holder.get('host')}"
    return f"process {holder['pid']}{where} since {holder.get('since')}"


class OutputLock:
    """``OUT.lock``: created exclusively by the one process writing OUT, removed when it is done.

    A lock whose process is gone (a killed run on this host) is taken over with a message.
    """

    def __init__(self, output, stream=None):
        self.output = Path(output)
        self.path = self.output.with_name(self.output.name + ".lock")
        self.stream = stream  # None: sys.stderr at the time of the message

    def _create(self) -> bool:
        try:
            fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            return False
        with os.fdopen(fd, "w") as f:
            json.dump({"pid": os.getpid(), "host": socket.gethostname(),
                       "since": time.strftime("%Y-%m-%d %H:%M:%S")}, f)
        return True

    def _holder(self) -> dict:
        try:
            holder = json.loads(self.path.read_text())
            return holder if isinstance(holder, dict) and isinstance(holder.get("pid"), int) else {}
        except (OSError, ValueError):
            return {}

    def acquire(self) -> None:
        for _ in range(3):
            if self._create():
                return
            holder = self._holder()
            if _running(holder):
                raise EnsembleFileError(f"{self.output}: already being written by {_who(holder)} (lock "
                                        f"{self.path}); wait for it to finish or choose another -o")
            what = f"process {holder['pid']} is gone" if holder else "it is unreadable"
            print(f"rss6: taking over the stale lock {self.path} ({what})", file=self.stream or sys.stderr)
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass
        raise EnsembleFileError(f"{self.output}: could not take the lock {self.path}")

    def running_holder(self) -> dict:
        """The holder ({pid, host, since}) of the lock while its process runs, else {}."""
        holder = self._holder()
        return holder if _running(holder) else {}

    def release(self) -> None:
        if self._holder().get("pid") == os.getpid():
            self.path.unlink(missing_ok=True)

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def parts_dir(output: Path) -> Path:
    """The folder OUTPUT.parts where a run keeps its finished chunks until the merged file is written."""
    return output.with_name(output.name + ".parts")


def unfinished(path) -> str | None:
    """Why ``path`` does not exist yet, when a run is writing it (its lock held by a running
    process) or stopped before it wrote it (its parts folder left), or None."""
    path = Path(path)
    lock, parts = OutputLock(path), parts_dir(path)
    holder = lock.running_holder()
    if holder:
        kept = f", its finished parts in {parts}" if parts.exists() else ""
        return f"not written yet: {_who(holder)} is still writing it (lock {lock.path}{kept}); wait for it to finish"
    if parts.exists():
        return (f"not written yet: the run writing it stopped with its finished parts in {parts}; "
                "rerun the command that writes it, with the same options, to finish it")
    return None


def sha256(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


MAX_NAMED = 5   # bad parts named in one refusal (the others counted)


class PartsManifest:
    """``OUT.nc.parts/manifest.json``: checksum, realisations and provenance of every stored part.

    A part is recorded in the manifest before it is renamed into place, so a crash leaves at worst
    an entry without a part (ignored), never a part without an entry. By default the parts of an
    ensemble (``rss6 run``); another command names its parts' ``index`` coordinate (listed as
    ``index + "s"`` in the manifest), what its items are called and the ``settings`` its provenance
    holds (e.g. ``rss6 sensitivity``: "row", "rows").
    """

    def __init__(self, folder: Path, provenance: dict, index: str = "realization", items: str = "realisations",
                 settings: str = "scene, model, integrator, step, mesh, seed or store"):
        self.folder, self.provenance = Path(folder), provenance
        self.index, self.items, self.settings = index, items, settings
        self.path = self.folder / "manifest.json"
        self.lost = False   # the parts' manifest was deleted or unreadable (:meth:`adopt`)
        self.entries = self._read()

    def _read(self) -> dict:
        if not self.path.exists():
            self.lost = any(self.folder.glob("*.nc"))
            return {}
        try:
            data = json.loads(self.path.read_text())
        except (OSError, ValueError):
            data = None
        if not self._well_formed(data):   # kept aside; its parts are then unvouched
            self.path.replace(self.path.with_name("manifest.json.unreadable"))
            self.lost = True
            return {}
        entries = data["parts"]
        if data.get("provenance") != self.provenance:
            raise EnsembleFileError(f"{self.path}: the parts were made with different settings "
                                    f"({self.settings}); choose another output file or the same settings")
        return entries

    def _well_formed(self, data) -> bool:
        """Whether ``data`` has the manifest's shape: a provenance and, per part, its sha256 and a list of its
        indices (an edited shape is read as a lost manifest, not as other settings or a traceback)."""
        key = self.index + "s"
        return (isinstance(data, dict) and isinstance(data.get("provenance"), dict)
                and isinstance(data.get("parts"), dict)
                and all(isinstance(e, dict) and isinstance(e.get("sha256"), str) and isinstance(e.get(key), list)
                        and e[key] and all(isinstance(r, int) for r in e[key]) for e in data["parts"].values()))

    def _save(self) -> None:
        tmp = self.path.with_name("manifest.json.tmp")
        tmp.write_text(json.dumps({"provenance": self.provenance, "parts": self.entries}, indent=1))
        os.replace(tmp, self.path)

    def write(self, ds, name: str) -> Path:
        """Write ``ds`` as part ``name``: to a temporary file, into the manifest, then into place."""
        self.folder.mkdir(parents=True, exist_ok=True)
        final, incoming = self.folder / name, self.folder / (name + ".incoming")
        with sigint_deferred():   # part, manifest entry and rename: all or nothing on Ctrl-C
            write_netcdf(ds, incoming)
            self.entries[name] = {"sha256": sha256(incoming), self.index + "s": [int(r) for r in ds[self.index].values]}
            self._save()
            os.replace(incoming, final)
        return final

    def adopt(self, path: Path, ds) -> None:
        """Vouch for part ``path`` (its Dataset ``ds``) of a lost manifest, once the caller has verified
        its values' own checksums and its identity: a deleted or unreadable manifest then costs no
        finished work (a part an intact manifest does not list stays refused: something else put it
        there)."""
        self.entries[path.name] = {"sha256": sha256(path), self.index + "s": [int(r) for r in ds[self.index].values]}
        self._save()

    def adoptable(self, path: Path) -> bool:
        """Whether part ``path`` is one the lost manifest would have listed (:meth:`adopt`)."""
        return self.lost and path.name not in self.entries

    def checked_parts(self, open_part) -> list:
        """Every stored part with its Dataset, after checking them all: the bad ones are named together
        in one EnsembleFileError (:meth:`refuse`). ``open_part(path, verify)`` returns a part's Dataset
        or raises UserError naming what is wrong with it. A part the manifest vouches for is not read
        again for its checksums (its bytes were); one of a deleted or unreadable manifest is, and is
        adopted (:meth:`adopt`) only if it carries them and they hold: with the manifest gone they are
        the only evidence that rss6 wrote its values."""
        problems, parts = {}, []
        for path in self.parts():
            problems[path] = self.problem(path)
            unvouched = self.adoptable(path)
            if problems[path] is not None and not unvouched:
                continue
            try:
                ds = open_part(path, unvouched)
            except UserError as exc:
                problems[path] = str(exc).removeprefix(f"{path}: ")
                continue
            if unvouched and ds.encoding.get("rss6_unverified"):
                problems[path] = "carries no checksums of its values"
                continue
            if unvouched:
                self.adopt(path, ds)
            problems[path] = None
            parts.append((path, ds))
        self.refuse(problems)
        return parts

    def problem(self, path: Path) -> str | None:
        """Why part ``path`` cannot be used (not listed in the manifest, or its bytes changed since it
        was written), or None."""
        entry = self.entries.get(path.name)
        if entry is None:
            return (f"not listed in {self.path.name}" if self.path.exists()
                    else f"no {self.path.name} vouches for it")
        if sha256(path) != entry["sha256"]:
            r = entry[self.index + "s"]
            return f"changed since it was written (checksum differs; {self.items} {r[0]}-{r[-1]})"
        return None

    def verify(self, path: Path) -> None:
        """Refuse a part the manifest does not list or whose bytes changed since it was written."""
        self.refuse({path: self.problem(path)})

    def refuse(self, problems: dict) -> None:
        """One EnsembleFileError naming every bad part of ``problems`` ({part: why or None}) and the
        one command that recovers: removing them (the folder, when all its parts are bad), after
        which the rerun computes their realisations again."""
        bad = {path: why for path, why in problems.items() if why}
        if not bad:
            return
        import shlex
        every = len(bad) == len(self.parts())
        remove = (f"rm -r {shlex.quote(str(self.folder))}" if every
                  else "rm " + " ".join(shlex.quote(str(p)) for p in bad))
        named = list(bad.items())[:MAX_NAMED]
        listed = "; ".join(f"{p.name}: {why}" for p, why in named) + (
            f"; and {len(bad) - len(named)} more" if len(bad) > len(named) else "")
        raise EnsembleFileError(f"{self.folder}: {len(bad)} of {len(self.parts())} stored parts cannot "
                                f"be used ({listed}); recover with `{remove}` and rerun the same command "
                                f"(it computes their {self.items} again)")

    def parts(self) -> list[Path]:
        return sorted(self.folder.glob("*.nc"))
