"""Reading MCAP files as a stranger would: the `mcap` reader and the schemas the file carries."""

from __future__ import annotations

import io
import json
from collections import Counter

import jsonschema
from mcap.reader import make_reader


def validated_topics(data: bytes) -> tuple[Counter[str], int, int]:
    """Validate every message of an MCAP file against the JSON schema stored with it; return
    the count per topic and the first and last log time, checked against the summary."""
    counts: Counter[str] = Counter()
    times: list[int] = []
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    reader = make_reader(io.BytesIO(data))
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        assert schema is not None and schema.encoding == "jsonschema", channel.topic
        assert channel.message_encoding == "json"
        if schema.id not in validators:
            validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
        validators[schema.id].validate(json.loads(message.data))
        counts[channel.topic] += 1
        times.append(message.log_time)
    summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None
    stats = summary.statistics
    by_topic = {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items()}
    assert by_topic == dict(counts)
    assert (stats.message_start_time, stats.message_end_time) == (min(times), max(times))
    return counts, min(times), max(times)
