"""The Delta *application transactions* the fleet lake's commits carry: a run's (two writers of
one run conflict on it), its identity values', the rewrites', and the stamps ingest sets; and how
often a commit that lost a race is tried again."""

from __future__ import annotations

from typing import Any, Final

from .schema import TableRun

#: How often a commit that lost a race with another transaction is tried again.
COMMIT_TRIES: Final = 50


def _app_id(robot: str, run: str) -> str:
    return f"objsearch/{robot}/{run}"


#: Set when the table is made: every commit of this table records its run's identity values as
#: application transactions (:func:`_identity_app`), so :meth:`TableLake.holding` answers "no
#: run holds these" from the log alone. A table made before has no such marker: it reads the
#: ``_run`` rows every time.
IDENTITY_INDEX_APP: Final = "objsearch/identity-index"
#: Set when the table is made: the commits of this table stamp what they record with
#: application transactions (``stamps`` of :meth:`TableLake.commit_as_read` and
#: :meth:`TableLake.commit_outside_runs`; ingest stamps each bag piece), so "is this bag here?" is
#: answered from the log alone. A table made before has no such marker: ingest reads its rows.
STAMP_INDEX_APP: Final = "objsearch/stamp-index"


#: Carried by every transaction that removes data files and writes their rows again (a
#: compaction, a replace, a removal), each at the version after the one its table read: of two
#: that overlap, the second fails and reads again. delta-rs (1.6.6) does not fail an append
#: whose remove actions name files another commit removed since (the rows they held, rewritten
#: by both, would be there twice: a replace that read the table between a compaction's claim
#: and its commit did so); a shared application transaction does.
REWRITE_APP: Final = "objsearch/rewrite"


def _rewrite_transaction(table: Any) -> Any:
    from deltalake import Transaction

    return Transaction(REWRITE_APP, (table.transaction_version(REWRITE_APP) or 0) + 1)


def _identity_app(key: str, value: str) -> str:
    return f"objsearch/identity/{key}={value}"


def _transactions(table: Any, info: TableRun) -> list[Any]:
    """The application transactions a commit of ``info`` carries: its run's (two writers of
    one run conflict on it) and one per identity value (the same for one recording)."""
    from deltalake import Transaction

    apps = [_app_id(info.robot, info.run)]
    apps += [_identity_app(k, v) for k, v in sorted(info.identity.items()) if v]
    return [Transaction(a, (table.transaction_version(a) or 0) + 1) for a in apps]


def stamp_version(table: Any) -> int:
    """The version a commit decided from ``table`` stamps with: past every version a commit
    decided from an earlier table stamped with (two commits decided from one table that stamp
    the same thing carry the same application transaction: one of them fails)."""
    return int(table.version()) + 1
