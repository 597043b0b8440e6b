"""What rosbags does with a damaged ROS 2 bag that the reader must not pass on as a traceback
or an open file.

- A ``metadata.yaml`` whose ``files`` entry is not a list (found by ``make fuzz``): rosbags
  keeps it as given, then fails to close the bag (``files.clear()``) before it closes the
  storage files, which stay open. :func:`empty_bad_files` empties it right after opening
  (rosbags reads the messages from ``relative_file_paths``, not from it).
- Any other failure to close: :func:`close_bag` returns it, so that the reader keeps what it
  read and notes it.
"""

from __future__ import annotations


def empty_bad_files(reader) -> bool:
    """Whether an opened AnyReader's ROS 2 bag had a ``files`` entry that is not a list; it is
    emptied (module doc)."""
    bad = False
    for inner in getattr(reader, "readers", ()):
        storage = getattr(inner, "storage", inner)
        if not isinstance(getattr(storage, "files", []), list):
            storage.files, bad = [], True
    return bad


def close_bag(reader) -> Exception | None:
    """Close the bag; a failure to close is returned, not raised (module doc)."""
    try:
        reader.close()
    except Exception as exc:  # noqa: BLE001  (rosbags raises many types for corrupt input)
        return exc
    return None
