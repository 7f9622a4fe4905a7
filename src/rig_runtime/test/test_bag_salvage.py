"""Salvage of a damaged MCAP file: every intact chunk kept, each gap named (time span, messages
lost per topic), with the summary there or not."""

from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader

from rig_runtime.bag import BagWriter
from rig_runtime.bag_recover import describe, recover_bag
from rig_runtime.interface import PITCH_STATE, WING_COEFFICIENTS
from rig_runtime.messages import new_message, serialize

T0 = 1_700_000_000 * 10**9
CHUNKS, PER_CHUNK, PERIOD_NS = 6, 300, 5_000_000
DAMAGED = 3  # a middle chunk

Record = tuple[str, int, bytes]  # topic, log time, data


def _write_bag(bag: Path) -> list[list[Record]]:
    """A bag of CHUNKS chunks (the writer flushed after each), each with PER_CHUNK messages per
    topic; the messages of each chunk."""
    writer = BagWriter(bag)
    pitch = writer.add_connection(PITCH_STATE.name, PITCH_STATE.type)
    wing = writer.add_connection(WING_COEFFICIENTS.name, WING_COEFFICIENTS.type)
    chunks: list[list[Record]] = []
    for c in range(CHUNKS):
        chunks.append([])
        for i in range(PER_CHUNK):
            k = c * PER_CHUNK + i
            t = T0 + k * PERIOD_NS
            state = serialize(new_message(PITCH_STATE.type, name=["pitch"], position=[k * 1e-3]))
            coeff = new_message(WING_COEFFICIENTS.type)
            coeff.vector.x = k * 1e-3
            for cid, topic, data in (
                (pitch, PITCH_STATE.name, state),
                (wing, WING_COEFFICIENTS.name, serialize(coeff)),
            ):
                writer.write(cid, t, data)
                chunks[-1].append((topic, t, data))
        writer.flush()  # closes the chunk
    writer.close()
    return chunks


def _chunk_indexes(file: Path) -> list[Any]:
    with file.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    indexes = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(indexes) == CHUNKS
    return indexes


def _damage(file: Path, offset: int, n: int = 64) -> None:
    data = bytearray(file.read_bytes())
    data[offset : offset + n] = bytes(b ^ 0xFF for b in data[offset : offset + n])
    file.write_bytes(bytes(data))


def _remove_summary(file: Path, indexes: list[Any]) -> None:
    """Cut the file after the last chunk and its message index (no DataEnd, summary, footer)."""
    last = indexes[-1]
    file.write_bytes(
        file.read_bytes()[: last.chunk_start_offset + last.chunk_length + last.message_index_length]
    )


def _records(file: Path) -> list[Record]:
    with file.open("rb") as f:
        return [
            (channel.topic, m.log_time, m.data)
            for _, channel, m in make_reader(f).iter_messages(log_time_order=False)
        ]


def _meta_count(bag: Path) -> int:
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return int(info["message_count"])


@pytest.mark.parametrize("summary", ["kept", "removed"])
def test_a_damaged_middle_chunk_costs_only_its_messages(tmp_path: Path, summary: str) -> None:
    bag = tmp_path / "bag"
    chunks = _write_bag(bag)
    file = bag / "bag_0.mcap"
    indexes = _chunk_indexes(file)
    bad = indexes[DAMAGED]
    _damage(file, bad.chunk_start_offset + bad.chunk_length // 2)  # its compressed records
    if summary == "removed":
        _remove_summary(file, indexes)
    reports = recover_bag(bag)
    assert len(reports) == 1
    report = reports[0]
    assert not report.intact and report.rewritten
    assert report.error == ("" if summary == "kept" else "cut short, no footer")
    # Every other chunk's messages, exactly; none of the damaged one's.
    kept = [r for c, records in enumerate(chunks) if c != DAMAGED for r in records]
    assert _records(file) == kept
    assert report.stats.count == _meta_count(bag) == len(kept)
    # The gap: the chunk's time span and its messages per topic.
    assert len(report.gaps) == 1
    gap = report.gaps[0]
    lost = chunks[DAMAGED]
    assert gap.exact and (gap.start_ns, gap.end_ns) == (lost[0][1], lost[-1][1])
    assert gap.span_from == ("chunk index" if summary == "kept" else "chunk header")
    assert gap.lost == {PITCH_STATE.name: PER_CHUNK, WING_COEFFICIENTS.name: PER_CHUNK}
    assert gap.offset == bad.chunk_start_offset
    lines = describe(reports)
    assert any(
        line.startswith("  gap: ") and f"{PITCH_STATE.name} {PER_CHUNK}" in line for line in lines
    ), lines
    # The rewritten file is whole: a second recovery leaves it as it is.
    before = file.read_bytes()
    assert recover_bag(bag)[0].intact and file.read_bytes() == before


@pytest.mark.parametrize("summary", ["kept", "removed"])
def test_broken_record_framing_resynchronises_on_the_next_chunk(
    tmp_path: Path, summary: str
) -> None:
    """The damage covers the end of the previous chunk's message index and the damaged chunk's
    header (its opcode and lengths): without a summary the walk finds the next chunk by its
    compression field and its CRC; the span is then bounded by the neighbouring readable
    messages and the count is unknown (the chunk's own index is not findable)."""
    bag = tmp_path / "bag"
    chunks = _write_bag(bag)
    file = bag / "bag_0.mcap"
    indexes = _chunk_indexes(file)
    _damage(file, indexes[DAMAGED].chunk_start_offset - 16, 48)
    if summary == "removed":
        _remove_summary(file, indexes)
    report = recover_bag(bag)[0]
    kept = [r for c, records in enumerate(chunks) if c != DAMAGED for r in records]
    assert _records(file) == kept
    assert len(report.gaps) == 1
    gap = report.gaps[0]
    if summary == "kept":  # the chunk index knows it
        assert gap.exact and gap.span_from == "chunk index"
        assert (gap.start_ns, gap.end_ns) == (chunks[DAMAGED][0][1], chunks[DAMAGED][-1][1])
        assert gap.lost == {PITCH_STATE.name: PER_CHUNK, WING_COEFFICIENTS.name: PER_CHUNK}
    else:
        assert not gap.exact and gap.span_from == "neighbouring readable messages"
        assert (gap.start_ns, gap.end_ns) == (chunks[DAMAGED - 1][-1][1], chunks[DAMAGED + 1][0][1])
        assert gap.lost is None
        assert "unknown count" in "\n".join(describe([report]))


def test_damage_to_a_message_index_alone_loses_nothing(tmp_path: Path) -> None:
    """Without a summary, damaged bytes that held only a chunk's message index records (their
    extent follows from the chunk's messages) cost no message and are not a gap."""
    bag = tmp_path / "bag"
    chunks = _write_bag(bag)
    file = bag / "bag_0.mcap"
    indexes = _chunk_indexes(file)
    ci = indexes[DAMAGED]
    _damage(file, ci.chunk_start_offset + ci.chunk_length + 5, 32)
    _remove_summary(file, indexes)
    report = recover_bag(bag)[0]
    assert report.gaps == [] and report.error == "cut short, no footer"
    assert _records(file) == [r for records in chunks for r in records]
