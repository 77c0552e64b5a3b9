"""What a bag claims and did not reach a sink, per topic (:func:`topic_losses`: in which damaged
chunks, else what is known) and as loss lines (:func:`unrecovered`)."""

from __future__ import annotations

from objsearch.pipeline.bags.readers import ReadOutcome, shortfall
from objsearch.pipeline.bags.report import MAX_REASONS, TopicLoss
from objsearch.pipeline.bags.salvage import Loss
from objsearch.pipeline.bags.sink import MessageSink


def topic_losses(outcome: ReadOutcome, sink: MessageSink) -> dict[str, TopicLoss]:
    """Per topic, the messages the bag claims and did not reach the sink, with where they went:
    the damaged chunks that held them (their index says how many), else what is known."""
    by_path = {scan.path: scan for scan in outcome.scans}
    in_chunks: dict[str, list[tuple[int, str]]] = {}
    for f in outcome.census.files:
        scan = by_path.get(f.path)
        if scan is None:
            continue
        for chunk, counts in sorted(f.chunks.items()):
            for cid, n in sorted(counts.items()):
                missing = n - scan.delivered[(chunk, cid)]
                topic = f.topics.get(cid)
                if missing > 0 and topic is not None:
                    in_chunks.setdefault(topic, []).append(
                        (
                            missing,
                            f"{missing} of {n} in the damaged chunk at byte {chunk} of {f.path.name}",
                        )
                    )
    out: dict[str, TopicLoss] = {}
    for topic, (got, n) in sorted(shortfall(outcome.claimed, sink.messages_per_topic()).items()):
        lost = n - got
        chunks = sorted(in_chunks.get(topic, []), key=lambda c: -c[0])
        reasons = [why for _, why in chunks[:MAX_REASONS]]
        if len(chunks) > MAX_REASONS:
            reasons.append(f"{len(chunks) - MAX_REASONS} more damaged chunk(s)")
        rest = lost - sum(m for m, _ in chunks)
        if rest > 0:
            reasons.append(
                f"{rest} the index lists that AnyReader skipped"
                if outcome.reader == "AnyReader"
                else f"{rest} not found in what could be read"
            )
        out[topic] = TopicLoss(n, lost, tuple(reasons))
    return out


def unrecovered(outcome: ReadOutcome, sink: MessageSink) -> list[Loss]:
    """Per-topic messages the bag says it had and that were not read, as loss lines."""
    return [
        Loss(
            f"topic {topic}",
            f"{loss.lost} of {loss.claimed} messages not read ({'; '.join(loss.reasons)})",
            loss.lost,
        )
        for topic, loss in topic_losses(outcome, sink).items()
    ]
