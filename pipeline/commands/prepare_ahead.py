"""``rss6 run``'s level prepared once in the workers' fork server, before it forks them.

``rss6 run`` starts the fork server ahead of its own imports (:func:`pipeline.cli.main`), handing
it the command line in :data:`PREPARE_ENV`.  The server imports this module last among its
preloads; it resolves the run's level as the command does (:func:`.run.ensemble_spec_of`) and
prepares it into the cache every chunk reads (:func:`pipeline.ensemble.run.shared_level`), so the
workers it forks inherit it: neither spends the elastic and paper levels' elastic run
(docs/performance.md section 34).  The level is a deterministic function of the same key, computed
with the workers' BLAS and hash settings, so the files do not change.  This is only a head start:
whatever goes wrong here (a typo, a missing file) is left, silently, for the command to report.
"""
from __future__ import annotations

import contextlib
import io
import json
import os

__all__ = ["PREPARE_ENV", "prepare", "prepare_from_environment"]

PREPARE_ENV = "RSS6_PREPARE_RUN"   # the rss6 run command line (JSON list) the fork server prepares for


def prepare(argv: list[str]) -> bool:
    """Prepare the level of ``rss6 run`` with ``argv`` (after ``run``) in this process's cache;
    whether it did (False, without a word, for a command line the command itself will refuse)."""
    from ..ensemble.run import shared_level
    from .run import ensemble_spec_of
    quiet = io.StringIO()
    with contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
        try:
            shared_level(ensemble_spec_of(argv))
        except (Exception, SystemExit):   # noqa: BLE001 (the command reports it, in its own words)
            return False
    return True


def prepare_from_environment() -> None:
    """In the fork server: prepare the level of the command line :data:`PREPARE_ENV` names, if any
    (removed from the environment, so that the workers do not see it)."""
    argv = os.environ.pop(PREPARE_ENV, None)
    if argv:
        prepare(json.loads(argv))


prepare_from_environment()
