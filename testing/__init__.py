"""objsearch.testing: the harnesses that break the store on purpose, kept out of the product.

``crashtest`` (forked writers SIGKILLed mid-append), ``killtest`` (a command killed after each of
its durable steps) and ``logfuzz`` (logs, repairs and snapshots damaged every way the format
can tell apart), and ``s3server`` (a local S3 server, moto's with its conditional writes made atomic, for the fleet lake on a bucket). The test suite, ``benchmarks/`` and the CLI's battery commands use them; no
product part imports this package, and it may import every part (``tests/test_architecture.py``).
"""
