"""docs/logs.md lists every column of every trial-log table."""

from pathlib import Path

from antarium.trial_log import FRAME_DTYPE, SAMPLE_DTYPE, _text_dtypes

DOC = (Path(__file__).resolve().parent.parent / "docs" / "logs.md").read_text()


def test_every_table_and_column_is_documented():
    tables = {"frames": FRAME_DTYPE, "locomotion": SAMPLE_DTYPE, **_text_dtypes()}
    for table, dtype in tables.items():
        assert f"`{table}`" in DOC, table
        for name in dtype.names:
            assert f"`{name}`" in DOC, (table, name)
