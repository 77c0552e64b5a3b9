"""devtools: the harnesses, fuzzers and batteries that break the product on purpose; not shipped.

A folder of the checkout, not a part of the ``objsearch`` package: pyproject's package-dir does
not list it, so the wheel never holds it (``tests/test_wheel.py``), and no product module imports
it (``tests/test_architecture.py``). The test suite finds it through pytest's ``pythonpath``,
``benchmarks/`` through the one ``sys.path`` line each script that uses it starts with, and
``make typecheck`` checks it with ``mypy -p devtools``. It may import every part of objsearch.

- the event log: ``crashtest`` (forked writers SIGKILLed mid-append), ``logfuzz`` (logs, repairs
  and snapshots damaged every way the format can tell apart), ``repair_battery`` (every kind of
  line damage at every line through ``objsearch log repair``);
- the fleet lake: ``killtest`` (a command killed after each of its durable steps),
  ``lake_battery``, ``lake_log_battery``, ``lake_fields_battery`` (damaged data files, damaged
  bookkeeping, every optional field) and ``s3server`` (moto's S3 server with its conditional
  writes made atomic);
- bags: ``bag_battery`` (seeded damage to copies of a bag, ingested by the CLI);
- the command line: ``cli_battery`` (every option of every subcommand with malformed values);
- the runtime: ``requestfuzz`` (broken requests against real agents) and ``wsflood`` (hostile
  WebSocket clients against the live view).
- the suite itself: ``xdist_scopes`` (how ``make test``'s workers share the test modules) and
  ``query_server`` (``objsearch query``'s process forked from a warm one, for the lake batteries).
"""
