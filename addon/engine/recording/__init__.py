"""Session recordings: MCAP files with every haptic tick (docs/recording-format.md), one module
a job: ``format`` (topics, the tick layout from the core, the header), ``writer`` (the writer
and the recorder thread), ``events`` (events derived from the ticks), ``reader`` (reading back,
``grasp-lab info``'s summary). Callers take the names below from here."""
from .events import EventDetector
from .format import (BLOCK_TICKS, FLAG_FORCES_ENABLED, FORMAT_VERSION, JSON_SCHEMA, PROFILE, REQUIRED_FIELDS,
                     STATE_NAMES, TICK_ENCODING, TICK_SCHEMA, TOPIC_END, TOPIC_EVENTS, TOPIC_HEADER, TOPIC_TICKS,
                     UNITS, RecordingError, addon_version, check_version, dtype_of, fingerprint, make_header,
                     scene_from_dict, scene_to_dict, schema_of, tick_dtype)
from .reader import Recording, open_recording, reuse_freed_memory, summarize
from .writer import (COMPRESSIONS, FLUSH_INTERVAL, RecordingWriter, SessionRecorder, set_stop_reason,
                     stop_reason)

__all__ = ["BLOCK_TICKS", "COMPRESSIONS", "FLAG_FORCES_ENABLED", "FLUSH_INTERVAL", "FORMAT_VERSION", "JSON_SCHEMA",
           "PROFILE", "REQUIRED_FIELDS", "STATE_NAMES", "TICK_ENCODING", "TICK_SCHEMA", "TOPIC_END", "TOPIC_EVENTS",
           "TOPIC_HEADER", "TOPIC_TICKS", "UNITS", "EventDetector", "Recording", "RecordingError",
           "RecordingWriter", "SessionRecorder", "addon_version", "check_version", "dtype_of", "fingerprint",
           "make_header", "open_recording", "reuse_freed_memory", "scene_from_dict", "scene_to_dict", "schema_of",
           "set_stop_reason", "stop_reason", "summarize", "tick_dtype"]
