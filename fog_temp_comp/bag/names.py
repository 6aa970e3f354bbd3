"""Names the command line shows: plain Python, so ``--help`` imports no bag library."""

#: bag formats this package writes (and reads)
FORMATS: tuple[str, ...] = ('mcap', 'sqlite3', 'ros1')
