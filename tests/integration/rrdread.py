"""An .rrd file read back with rerun-sdk's own reader (``rerun.chunk.RrdReader``): each entity's
rows, each with its timelines' values and its components' cells, as Rerun stored them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ROW_ID = "rerun.controls.RowId"
TIMELINES = ("capture_time", "frame_id", "log_time")


@dataclass
class Row:
    times: dict[str, int] = field(default_factory=dict)  # timeline -> int value (ns for times)
    cells: dict[str, object] = field(default_factory=dict)  # "Archetype:component" -> the row's value

    @property
    def capture_ns(self) -> int:
        return self.times["capture_time"]

    @property
    def frame_id(self) -> int | None:
        return self.times.get("frame_id")


@dataclass
class Recording:
    entities: dict[str, list[Row]]  # entity path -> its rows logged on timelines, in capture-time order
    static: dict[str, dict[str, object]]  # entity path -> its static cells

    def cells(self, entity: str, component: str) -> list:
        return [row.cells[component] for row in self.entities[entity]]


def read_rrd(path) -> Recording:
    from rerun.chunk import RrdReader

    rows: dict[str, dict[bytes, Row]] = {}
    static: dict[str, dict[str, object]] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        components = [n for n in names if n != ROW_ID and n not in TIMELINES]
        columns = {n: batch.column(n) for n in names}
        if chunk.is_static:
            for name in components:
                static.setdefault(chunk.entity_path, {})[name] = columns[name][0].as_py()[0]
            continue
        entity = rows.setdefault(chunk.entity_path, {})
        for i, row_id in enumerate(columns[ROW_ID].to_pylist()):
            row = entity.setdefault(row_id, Row())  # one log call's components may sit in chunks of their own
            for timeline in TIMELINES:
                if timeline in columns and columns[timeline][i].is_valid:
                    row.times[timeline] = columns[timeline].cast("int64")[i].as_py()
            for name in components:
                cell = columns[name][i].as_py()
                row.cells[name] = cell[0] if isinstance(cell, list) and len(cell) == 1 else cell
    ordered = {path: sorted(by_id.values(), key=lambda r: r.capture_ns) for path, by_id in rows.items()}
    return Recording(ordered, static)


def image_of(row: Row) -> np.ndarray:
    """The pixels of a row of an ``Image`` entity, (h, w) or (h, w, c)."""
    form = row.cells["Image:format"]
    pixels = np.array(row.cells["Image:buffer"], dtype=np.uint8)
    image = pixels.reshape(form["height"], form["width"], -1)
    return image[:, :, 0] if image.shape[2] == 1 else image
