"""``fxis record --recover``: a bag whose recording was killed (kill -9, a power cut) made
readable up to its last complete message, as ``ros2 bag reindex`` does for rosbag2.

The repaired .mcap file (fxis_shm.formats.mcaprecover) is written next to the damaged one
and swapped in by a rename, so the bag's file is at every moment either the damaged one or
the repaired one; the damaged one stays as ``NAME.mcap.damaged``. metadata.yaml follows,
with the counts and times of what the file now holds.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

from fxis_shm.errors import FxisError
from fxis_shm.formats.bagfile import (
    BEGUN_RECORD,
    METADATA_FILE,
    RECORD,
    RESERVE_FILE,
    BagReader,
    bag_info,
    mcap_file,
    require_mcap,
    write_metadata,
)

if TYPE_CHECKING:
    from fxis_shm.formats.mcaprecover import McapIndex, Repair

KILLED = "the writer stopped without closing the bag (killed?): recovered up to its last complete message"


@dataclass
class Recovered:
    """What ``recover_bag`` did: ``repair`` is None if the .mcap file was whole."""

    folder: str
    file: str
    topics: dict[str, tuple[str, int]]  # topic -> (message type, messages)
    start_time: int
    end_time: int
    repair: Repair | None = None
    damaged: str = ""  # where the damaged original was kept
    wrote_metadata: bool = False


def recover_bag(path: str) -> Recovered:
    """Make the bag at ``path`` (folder or .mcap file) readable up to its last complete
    message, as ``ros2 bag reindex`` does: the repaired file is written next to the damaged
    one and swapped in (the original kept as ``.mcap.damaged``), then metadata.yaml."""
    require_mcap("fxis record --recover")
    from fxis_shm.formats.mcaprecover import examine

    file = mcap_file(path)
    folder = os.path.dirname(file) if os.path.isfile(path) else path
    with contextlib.suppress(FileNotFoundError):
        os.remove(os.path.join(folder, RESERVE_FILE))  # a killed recorder's: room for the copy
    reader = BagReader(file)
    if reader.repair is None and os.path.exists(os.path.join(folder, METADATA_FILE)):
        return Recovered(folder, file, {}, reader.start_time, reader.end_time)
    # damaged: made whole, ending on a complete ``fxis`` record; or whole without metadata.yaml: its counts
    repair = examine(file, _last_word) if reader.repair is not None else examine(file)
    index = repair.index
    done = Recovered(folder, file, index.topics(), index.start_time, index.end_time, wrote_metadata=True)
    if reader.repair is not None:
        done.repair, done.damaged = repair, _free_name(file + ".damaged")
        try:
            repair.write_to(file + ".recovering")
        except OSError as exc:
            raise FxisError(f"{file}: the repaired copy could not be written ({exc}); the bag is unchanged") from None
        try:
            os.link(file, done.damaged)  # the original stays under its own name until the swap
        except OSError:
            os.rename(file, done.damaged)  # no hard links here (FAT): a moment without the file
        os.replace(file + ".recovering", file)
    custom = index.metadata.get(RECORD) or index.metadata.get(BEGUN_RECORD, {})
    first = index.start_time if index.message_count else None
    write_metadata(folder, bag_info(os.path.basename(file), done.topics, first, index.end_time, custom))
    return done


def _last_word(index: McapIndex) -> dict[str, dict[str, str]]:
    """The ``fxis`` record a killed writer did not write: what it knew when it began, and how it ended."""
    if RECORD in index.metadata:
        return {}
    return {RECORD: {**index.metadata.get(BEGUN_RECORD, {}), "ended": KILLED}}


def _free_name(path: str) -> str:
    name, n = path, 1
    while os.path.exists(name):
        name, n = f"{path}.{n}", n + 1
    return name
