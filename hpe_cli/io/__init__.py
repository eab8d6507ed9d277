"""Thin I/O: the label table layout, streaming readers, atomic writers, rejects."""

from .labels import (
    batch_labels,
    batch_rotations,
    label_columns_fast,
    label_mode,
    numeric_column,
    rotation_value_columns,
)
from .layout import (
    ANGLE2_COLS,
    ANGLE_COLS,
    BBOX_COLS,
    LABEL_COLS,
    MATRIX_COLS,
    arrow_table,
    conversion_columns,
    landmark_cols,
    landmark_count,
)
from .readers import TableSource, open_table, read_table
from .rejects import Rejects
from .writers import AtomicFile, TableWriter, check_output, system_metadata, table_format, write_json, write_table
