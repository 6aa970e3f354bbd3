"""``fog-temp-comp compensate``: replay a bag through the compensator; inputs + corrected Imu out.

The output is complete or absent (:class:`~fog_temp_comp.tools.atomic.AtomicOutputs`); a bag
whose damage shows only when read is repaired and replayed. MCAP bags take the block path
(:mod:`~fog_temp_comp.tools.blockreplay`), others the chunk path
(:mod:`~fog_temp_comp.tools.chunkreplay`); the optional bias learner at rest reads and writes
learned-bias files (deg/h).
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from fog_temp_comp.bag import bagio, mcapwrite
from fog_temp_comp.bag.bag_path import inside_bag, misnamed_output
from fog_temp_comp.bag.bagio import BagError, BagWriter
from fog_temp_comp.bag.one_clock import on_one_clock
from fog_temp_comp.bag.repair import repaired_bag
from fog_temp_comp.bag.salvage import Salvage
from fog_temp_comp.bag.streamdecode import check_field
from fog_temp_comp.bag.temperature_topic import resolve_temperature
from fog_temp_comp.bag.topic_names import (
    OUTPUT_SUFFIX,
    check_topic_name,
    default_output_topic,
    output_topic_for,
)
from fog_temp_comp.bag.unstamped import ClocksApartError, UnsetStamps
from fog_temp_comp.core.coefficients import Coefficients, load
from fog_temp_comp.core.compensator import Compensator, CompensatorCounters, GuardSettings
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.rest import RestLearner, RestSettings
from fog_temp_comp.core.restfile import (
    check_learned_bias,
    file_sha256,
    learned_bias_from_status,
    read_learned_bias,
    write_learned_bias,
)
from fog_temp_comp.tools import blockreplay
from fog_temp_comp.tools.atomic import AtomicOutputs, check_output_directory
from fog_temp_comp.tools.chunkreplay import ChunkReplayer, chunked
from fog_temp_comp.tools.compensate_report import check_temperature_used, report_input
from fog_temp_comp.tools.evaluate_command import effective_settings, frame_mismatch
from fog_temp_comp.tools.salvaged import Salvaged
from fog_temp_comp.tools.temperature_sources import with_yaml_temperature_topic

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader


def compensate_command(
    in_bag: Path,
    coeffs_path: Path,
    out_bag: Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    temp_field: str | None = None,
    temp_frame_id: str = '',
    output_topic: str | None = None,
    denoise_method: str | None = None,
    guard: GuardSettings | None = None,
    strict: bool = False,
    rest: RestSettings | None = None,
    rest_bias_in: Path | None = None,
    rest_bias_out: Path | None = None,
    time_source: str = 'header',
    stdout: TextIO | None = None,
    fast: bool = True,
) -> int:
    """Replay ``in_bag`` through a :class:`Compensator`; write all inputs plus corrected Imu.

    Messages are processed in the bag's log-time order, i.e. the order a node sees on replay.
    ``fast`` (the default) reads an MCAP bag a chunk at a time and writes blocks
    (:mod:`~fog_temp_comp.tools.blockreplay`), other bags through ``AnyReader`` and
    :meth:`BagWriter.write_many`; ``fast=False`` writes through rosbags one message at a time.
    Both give the same bag. With ``rest`` (enabled) the bias learner at rest runs too, fed the
    Imu's accelerometer (through ``AnyReader``: the MCAP block path decodes rates only); it
    starts from the learned-bias file ``rest_bias_in`` (refused with an error if learned with
    other coefficients) and writes what it learned to ``rest_bias_out``
    (:mod:`~fog_temp_comp.core.restfile`, as the node's ``rest_bias_file``). ``time_source``
    ``'receive'`` times gyro and temperature by their receive times, not their header stamps
    (drivers on two clocks, which the default warns about); the output keeps the headers.
    ``temp_field`` reads the temperature (degC) from a field of ``temp_topic``'s messages of
    any type (through ``AnyReader``); without them, what the coefficients were fitted on
    (:func:`~fog_temp_comp.tools.temperature_sources.with_yaml_temperature_topic`).
    ``temp_frame_id`` (default: the coefficients' ``temperature_frame_id``) picks one sensor's
    readings of a topic that carries several.
    ``output_topic``: :func:`~fog_temp_comp.bag.topic_names.output_topic_for` (by default
    ``<ns>/data`` of ``<ns>/data_raw``, else the gyro topic + ``_compensated``).
    """
    stdout = stdout or sys.stdout
    coeffs = load(coeffs_path)
    _check_output(in_bag, out_bag)  # before the bag is read
    settings = effective_settings(coeffs, denoise_method)
    if (rest_bias_in or rest_bias_out) and not (rest is not None and rest.enabled):
        raise ValueError('--rest-bias-in/--rest-bias-out need --rest-learning')

    def new_compensator(out: TextIO | None = None) -> Compensator:
        compensator = Compensator(coeffs.model, settings, guard, rest)
        if rest_bias_in is not None:
            _start_rest_from(compensator, rest_bias_in, coeffs_path, out)
        return compensator

    new_compensator(stdout)  # refuse a learned-bias file that does not fit, before reading
    if temp_field is not None and temp_topic is None:
        raise BagError('--temp-field needs --temp-topic (the topic that carries the field)')
    if output_topic and not output_topic.startswith('/'):
        output_topic = '/' + output_topic
    if output_topic:
        check_topic_name(output_topic, '--output-topic')
    run = _Compensate(
        in_bag=in_bag,
        fmt=bagio.bag_format(in_bag),
        topics=(gyro_topic, temp_topic, output_topic),
        new_compensator=new_compensator,
        fast=fast,
        by_receive=time_source == 'receive',
        temp_field=temp_field,
        temp_frame_id=temp_frame_id or coeffs.temperature_frame_id,
    )
    (n_out, counters), compensator = run.replay(out_bag, strict, coeffs)
    if (mismatch := frame_mismatch(in_bag, run.gyro_frame, coeffs.frame_id)) is not None:
        print(mismatch, file=sys.stderr)
    _report_written(run, out_bag, n_out, counters, chosen=output_topic is None, stdout=stdout)
    report_input(run.in_bag, compensator)  # faults, gaps, NaN gyro
    if compensator.rest is not None:
        _report_rest(compensator.rest, coeffs_path, rest_bias_out, stdout)
    return 0


def _check_output(in_bag: Path, out_bag: Path) -> None:
    """Refuse an ``-o`` that cannot be the output, before the bag is read.

    One that exists, lies inside the input's bag directory (read as part of it afterwards), is
    named as a bag of another format, or whose directory is missing.
    """
    if out_bag.exists():
        raise FileExistsError(f'{out_bag}: exists already, not overwriting')
    if (inside := inside_bag(out_bag, in_bag)) is not None:
        raise ValueError(inside)
    if (misnamed := misnamed_output(out_bag, bagio.bag_format(in_bag))) is not None:
        raise ValueError(misnamed)
    check_output_directory(out_bag)


def _report_written(
    run: _Compensate,
    out_bag: Path,
    n_out: int,
    counters: CompensatorCounters,
    *,
    chosen: bool,
    stdout: TextIO,
) -> None:
    """The output line; a ``NOTE:`` first where the default output topic was in the input."""
    used = str(run.output_used)
    preferred = default_output_topic(used.removesuffix(OUTPUT_SUFFIX))  # of the gyro topic
    if chosen and used.endswith(OUTPUT_SUFFIX) and used != preferred:
        print(
            f'NOTE: {preferred} is a topic of {run.in_bag}: the corrected Imu goes '
            f'to {run.output_used} (choose another with --output-topic)',
            file=stdout,
        )
    if counters.time_jumps:
        print(
            f'WARNING: {run.in_bag}: {counters.time_jumps} time jumps (two gyro stamps in a row '
            'behind the one before by the time-jump threshold, 1 s by default, or more: a bag '
            'looped, or a stretch recorded twice after the rest) restarted the correction, '
            'which waited for a temperature after each',
            file=sys.stderr,
        )
    if counters.imu_out_of_order:
        print(
            f'WARNING: {run.in_bag}: {counters.imu_out_of_order} gyro stamps behind the one '
            'before (out of order in the bag, or a stretch recorded twice, between live '
            'messages) got the correction of the moment they came, next to them',
            file=sys.stderr,
        )
    if n_out and counters.imu_uncorrected == n_out:
        print(
            f'WARNING: {run.in_bag}: none of the {n_out} gyro messages was corrected: each '
            'passed through as it came (no temperature within the stale time of its stamp); '
            f'{run.output_used} holds the raw rate',
            file=sys.stderr,
        )
    after = ' or after a time jump' if counters.time_jumps else ''
    held = f'{counters.imu_held} with the correction held, ' if counters.imu_held else ''
    print(
        f'wrote {out_bag}: {n_out} Imu on {run.output_used}: '
        f'{n_out - counters.imu_uncorrected - counters.imu_held} corrected, '
        f'{held}{counters.imu_uncorrected} passed through uncorrected '
        f'({counters.imu_awaiting_temperature} before the first temperature{after} and '
        f'{counters.imu_duplicate} duplicates not written)',
        file=stdout,
    )


def _on_one_clock(
    run: _Compensate, in_bag: Path, out_bag: Path, strict: bool
) -> tuple[tuple[int, CompensatorCounters], Compensator]:
    """:func:`_replay_atomically`, again by receive time where the clocks are hours apart."""

    def replay(bag: Path, time_source: str) -> tuple[tuple[int, CompensatorCounters], Compensator]:
        run.by_receive = time_source == 'receive'
        return _replay_atomically(run, bag, out_bag, strict)

    return on_one_clock(replay, in_bag, time_source='receive' if run.by_receive else 'header')


def _replay_atomically(
    run: _Compensate, in_bag: Path, out_bag: Path, strict: bool
) -> tuple[tuple[int, CompensatorCounters], Compensator]:
    """``run`` into ``out_bag``, complete or not at all: (written, counters), the compensator.

    A bag whose damage shows only when read is repaired (what is intact copied) and replayed.
    A single ``.mcap`` or ``.db3`` file in gives one out where ``out_bag`` ends so
    (:func:`_as_single_file`).
    """
    with AtomicOutputs(out_bag) as out:  # complete, or nothing at out_bag
        target = out.path(out_bag)
        try:
            with repaired_bag(in_bag, out_bag.parent, strict=strict) as (source, salvage):
                result = run.into(target, source, salvage)
        except ReplayError as err:  # damage that shows only when read: copy what is intact
            remove_bag(target)
            with repaired_bag(in_bag, out_bag.parent, strict=strict, failure=err) as (
                source,
                salvage,
            ):
                result = run.into(target, source, salvage)
        if not result[0][1].imu_total:  # an output without a corrected gyro is not a result
            raise BagError(
                f'{in_bag}: no gyro message was read (an empty gyro topic, or a bag whose '
                'metadata.yaml does not match its data)'
            )
        check_temperature_used(in_bag, run.topics[1], result[0][1])
        if in_bag.is_file() and out_bag.suffix == _FILE_SUFFIX.get(run.fmt):
            _as_single_file(target)
        return result


#: the data file's suffix of a one-file ROS 2 bag, per storage format
_FILE_SUFFIX = {'mcap': '.mcap', 'sqlite3': '.db3'}


def _as_single_file(bag: Path) -> None:
    """Replace the rosbag2 directory ``bag`` by its one data file, under the name ``bag``.

    ``compensate run.mcap -o out.mcap`` gives a file, as it was given one (the MCAP file holds
    its schemas, the sqlite3 file its topics: ``metadata.yaml`` is not needed to read it).
    """
    (data,) = [f for f in bag.iterdir() if f.name != 'metadata.yaml']
    moved = bag.with_name(bag.name + '.data')
    os.replace(data, moved)
    shutil.rmtree(bag)
    os.replace(moved, bag)


def _report_rest(
    learner: RestLearner, coeffs_path: Path, rest_bias_out: Path | None, stdout: TextIO
) -> None:
    """Print what the bias learner at rest learned (deg/h); write it to ``rest_bias_out``."""
    st = learner.finish()
    print(
        f'rest learning: {st.windows_rest} rest windows learned from, '
        f'{st.windows_motion} moving, {st.windows_tilting} tilting, '
        f'{st.windows_over_limit} over the limit; learned '
        + ', '.join(f'{v:.3f}' for v in st.learned_deg_h)
        + ' deg/h (x, y, z), applied '
        + ', '.join(f'{v:.3f}' for v in st.applied_deg_h)
        + ' deg/h',
        file=stdout,
    )
    if rest_bias_out is None:
        return
    bias = learned_bias_from_status(
        st,
        learner.settings,
        coefficients_file=str(coeffs_path),
        coefficients_sha256=file_sha256(coeffs_path),
    )
    if bias is None:
        print(f'rest learning: nothing learned, {rest_bias_out} not written', file=stdout)
    else:
        write_learned_bias(rest_bias_out, bias)
        print(f'wrote {rest_bias_out} (learned bias)', file=stdout)


class ReplayError(BagError):
    """Reading the input failed while replaying it (a damaged bag: copied and tried again)."""


@dataclass
class _Compensate:
    """The settings of one ``compensate`` run, applied to a (possibly repaired) input."""

    in_bag: Path
    fmt: str
    topics: tuple[str | None, str | None, str | None]  # gyro, temperature, output
    new_compensator: Callable[[], Compensator]
    fast: bool
    #: gyro and temperature timed by receive time (``--time-source receive``)
    by_receive: bool = False
    #: the corrected Imu's topic, once the input's topics are known (:func:`output_topic_for`)
    output_used: str | None = None
    #: the temperature is this field of the temperature topic's messages (``--temp-field``)
    temp_field: str | None = None
    #: of a temperature topic with several sensors' readings, this one's ('': choose)
    temp_frame_id: str = ''
    #: the gyro topic's first frame_id (None: not read)
    gyro_frame: str | None = None

    def replay(
        self, out_bag: Path, strict: bool, coeffs: Coefficients
    ) -> tuple[tuple[int, CompensatorCounters], Compensator]:
        """:func:`_on_one_clock` with the temperature the coefficients were fitted on.

        Where no topic or field was asked for, ``coeffs``' temperature topic and field
        (:func:`~fog_temp_comp.tools.temperature_sources.with_yaml_temperature_topic`).
        """
        gyro_topic, temp_topic, output_topic = self.topics

        def on_topic(
            topic: str | None, field: str | None
        ) -> tuple[tuple[int, CompensatorCounters], Compensator]:
            self.topics = (gyro_topic, topic, output_topic)
            self.temp_field = field
            return _on_one_clock(self, self.in_bag, out_bag, strict)

        return with_yaml_temperature_topic(
            on_topic, coeffs, temp_topic, self.temp_field, sys.stderr
        )

    def _temperature_topic(self, reader: AnyReader, temp_topic: str | None, imu_name: str) -> str:
        """The temperature topic, by ``temperature_topic.resolve_temperature``.

        Where it is read as a field (``--temp-field``, a bare number's ``data``), that field
        is checked and set as :attr:`temp_field`, the topic in :attr:`topics` (a repaired copy
        reads the same without a second ``NOTE:``).
        """
        topics = {name: info.msgtype or '' for name, info in reader.topics.items()}
        name, field = resolve_temperature(topics, temp_topic, self.temp_field, imu_name)
        if field is not None:
            check_field(reader.typestore, topics[name], field)
        self.temp_field = field
        self.topics = (self.topics[0], name, self.topics[2])
        return name

    def _unset_stamps(self, imu_name: str, temp_name: str) -> UnsetStamps:
        """What times the messages; by header, it stops at clocks hours apart."""
        if self.by_receive:
            return UnsetStamps(by_receive=True)
        return UnsetStamps(watch=(imu_name, temp_name))

    def into(
        self, target: Path, source: Path, salvage: Salvage | None
    ) -> tuple[tuple[int, CompensatorCounters], Compensator]:
        """Write ``target`` from ``source``; (written, counters) and the compensator used.

        ``salvage`` (a repaired copy) is reported on stderr, and the spans it skipped inside
        the run are temperature gaps (:meth:`Compensator.mark_holes`): the Kalman filter
        bridges them, another estimator restarts there.
        """
        if salvage is not None:
            Salvaged().add(salvage)
        holes = [(a, b) for a, b in (salvage.gap_spans_s() if salvage else []) if b is not None]
        gyro_topic, temp_topic, output_topic = self.topics
        compensator = self.new_compensator()
        compensator.mark_holes(holes)
        opened = ExitStack()
        try:
            reader = opened.enter_context(bagio.open_bag(source))
        except BagError as err:
            if salvage is not None:
                raise
            raise ReplayError(str(err)) from err  # a stale metadata.yaml, ...: copy it
        with opened:
            imu_name = bagio.resolve_topic(reader, gyro_topic, bagio.IMU_TYPE, '--gyro-topic')
            self.output_used = output_topic_for(output_topic, imu_name, reader.topics, self.in_bag)
            self.gyro_frame = bagio.first_frame_id(reader, imu_name)
            temp_name = self._temperature_topic(reader, temp_topic, imu_name)
            job = _CompensateJob(
                reader=reader,
                in_bag=self.in_bag,
                out_bag=target,
                fmt=self.fmt,
                imu_name=imu_name,
                temp_name=temp_name,
                temp_field=self.temp_field,
                output_topic=self.output_used,
                compress=self.fmt == 'mcap' and _compressed_mcap(source),
                unstamped=self._unset_stamps(imu_name, temp_name),
                frames=FrameLock(self.temp_frame_id),
                number_type=blockreplay.number_type(reader, temp_name, self.temp_field),
            )
            mcap = None
            block = (
                self.fast
                and reader.is2
                and compensator.rest is None
                and (self.temp_field is None or job.number_type is not None)
            )
            if block and not blockreplay.per_message_compressed(reader):
                mcap = blockreplay.single_mcap_file(source)
            if mcap is not None:
                try:
                    result = job.run(compensator, mcap=mcap)
                    job.warn(self.in_bag)
                    return result, compensator
                except (blockreplay.UnsupportedError, ValueError):
                    remove_bag(target)  # the per-message path decides (and words any error)
                    compensator = self.new_compensator()
                    compensator.mark_holes(holes)
                    job.unstamped = self._unset_stamps(imu_name, temp_name)
                    job.frames = FrameLock(self.temp_frame_id)
            result = job.run(compensator, batched=self.fast)
            job.warn(self.in_bag)
            return result, compensator


def _start_rest_from(
    compensator: Compensator, path: Path, coeffs_path: Path, out: TextIO | None
) -> None:
    """Start the bias learner from a learned-bias file; ValueError if it does not fit."""
    assert compensator.rest is not None
    bias = read_learned_bias(path)
    check_learned_bias(
        bias,
        coefficients_sha256=file_sha256(coeffs_path),
        earth_rate_body_deg_h=compensator.rest.settings.earth_rate_body_deg_h,
        path=path,
    )
    reason = compensator.rest.start_from(bias.bias_deg_h)
    if reason is not None:
        raise ValueError(f'{path}: {reason}')
    if out is not None:
        text = ', '.join(f'{v:.3f}' for v in bias.bias_deg_h)
        print(f'rest learning: starting from {text} deg/h (x, y, z), {path}', file=out)


def _compressed_mcap(bag: Path) -> bool:
    """Whether an MCAP bag's (first file's first) chunk is compressed."""
    files = [bag] if bag.is_file() else sorted(bag.glob('*.mcap'))
    return bool(files) and mcapwrite.chunk_compression(files[0]) != ''


@dataclass
class _CompensateJob:
    """One ``compensate`` output: the input reader, the topics, where to write."""

    reader: Any
    in_bag: Path
    out_bag: Path
    fmt: str
    imu_name: str
    temp_name: str
    output_topic: str
    compress: bool = False
    #: unset header stamps (0) that took the receive time, per topic
    unstamped: UnsetStamps = dataclasses.field(default_factory=UnsetStamps)
    #: the temperature is this field of ``temp_name``'s messages (``--temp-field``)
    temp_field: str | None = None
    #: of a temperature topic with several sensors' readings (frame_ids), the one kept
    frames: FrameLock = dataclasses.field(default_factory=FrameLock)
    #: the temperature is a bare ``std_msgs/Float64``/``Float32`` of this type (its ``data``)
    number_type: str | None = None

    def warn(self, in_bag: Path) -> None:
        """The warnings on the input's stamps, a note on its temperature frame_ids (stderr)."""
        self.unstamped.warn(in_bag, topics=(self.imu_name, self.temp_name))
        note = self.frames.note(str(in_bag), self.temp_name)
        if note is not None:
            print(note, file=sys.stderr)

    def run(
        self, compensator: Compensator, *, mcap: Path | None = None, batched: bool = True
    ) -> tuple[int, CompensatorCounters]:
        """Write the output bag; (corrected Imu written, the compensator's counters).

        With ``mcap``, :class:`blockreplay.UnsupportedError` and ``ValueError`` (damaged file)
        pass through for the caller to fall back; other errors become :class:`BagError`.
        The output is removed on any error.
        """
        try:
            with BagWriter(self.out_bag, self.fmt, compress=self.compress) as writer:
                self._add_topics(writer)
                if mcap is not None:
                    n_out = blockreplay.replay_mcap(
                        mcap,
                        writer,
                        compensator,
                        topics=set(self.reader.topics),
                        imu_topic=self.imu_name,
                        temp_topic=self.temp_name,
                        output_topic=self.output_topic,
                        unstamped=self.unstamped,
                        frames=self.frames,
                        number_type=self.number_type,
                    )
                else:
                    n_out = self._replay_messages(writer, compensator, batched)
        except Exception as err:
            remove_bag(self.out_bag)  # no half-written output
            if isinstance(err, (BagError, ClocksApartError)) or (
                mcap is not None and isinstance(err, (blockreplay.UnsupportedError, ValueError))
            ):
                raise
            raise ReplayError(
                f'{self.in_bag}: failed while replaying (damaged bag?): {err}'
            ) from err
        return n_out, compensator.status.counters

    def _add_topics(self, writer: BagWriter) -> None:
        reader = self.reader
        for conn in reader.connections:
            if conn.topic not in writer.topics:
                writer.add_topic(conn.topic, conn.msgtype, like=conn)
        imu_conn = next(c for c in reader.connections if c.topic == self.imu_name)
        # ROS 1: the corrected messages keep the input's layout (Header with seq)
        writer.add_topic(
            self.output_topic, bagio.IMU_TYPE, like=imu_conn if self.fmt == 'ros1' else None
        )

    def _replay_messages(self, writer: BagWriter, compensator: Compensator, batched: bool) -> int:
        """Through ``AnyReader``, a chunk at a time, written as a block or one by one."""
        messages = bagio.temperature_first(self.reader.messages(), self.temp_name)
        replayer = ChunkReplayer(
            compensator,
            self.reader,
            self.imu_name,
            self.temp_name,
            self.unstamped,
            temp_field=self.temp_field,
            frames=self.frames,
        )
        n_out = 0
        for chunk in chunked(messages, 20_000):
            out = [(topic or self.output_topic, ns, raw) for topic, ns, raw in replayer.run(chunk)]
            n_out += len(out) - len(chunk)
            if batched:
                writer.write_many(out)
            else:
                for topic, log_ns, raw in out:
                    writer.write_raw(topic, log_ns, raw)
        return n_out


def remove_bag(path: Path) -> None:
    """Delete a bag file or directory if it exists."""
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()
