"""Names the command line shows: plain Python, so ``--help`` imports no bag library."""

#: bag formats this package writes (and reads)
FORMATS: tuple[str, ...] = ('mcap', 'sqlite3', 'ros1')
#: how gyro and temperature are aligned: header stamps or the bag's receive time
TIME_SOURCES: tuple[str, ...] = ('header', 'receive')
