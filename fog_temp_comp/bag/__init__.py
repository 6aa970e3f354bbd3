"""Bag input and output: read chamber runs from ROS 1 and ROS 2 bags, write bags.

``cdr`` (vectorised CDR / ROS 1 codecs), ``mcapscan``, ``sqlitescan`` and ``ros1scan`` (fast
readers; ``mcapscan`` built on ``mcapformat``, ``mcapreader``, ``mcapbatches`` and ``mcapinfo``),
``bagio`` (rosbags-based reading and writing, message builders), ``mcapwrite``,
``sqlitewrite`` and ``ros1write`` (blocks of messages into rosbags' writers), ``stream``
(:class:`~fog_temp_comp.bag.stream.BagStream`: one bag's gyro and temperature in chunks, and
``read_record``; its read paths in ``mcapstream``, ``sqlitestream`` and ``ros1stream``, their
shared decoding in ``streamdecode``, ``streamchunk`` and ``progress``) and ``reduce`` (a bag to
10 s grid means while streaming).

May import: ``fog_temp_comp.core`` and ``fog_temp_comp.bag`` (and rosbags, apsw, numpy).
"""
