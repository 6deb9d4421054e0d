"""A file written atomically is either its old content or the whole new one."""
import os

import pytest
from robotenis_kinematics import files


def test_text_and_bytes_are_written_and_nothing_else_is_left(tmp_path):
    files.write_atomic(tmp_path / 'a.yaml', 'x: 1\n')
    files.write_atomic(str(tmp_path / 'b.png'), b'\x89PNG')
    assert (tmp_path / 'a.yaml').read_text() == 'x: 1\n'
    assert (tmp_path / 'b.png').read_bytes() == b'\x89PNG'
    assert sorted(os.listdir(tmp_path)) == ['a.yaml', 'b.png']


def test_a_failed_write_keeps_the_old_content_and_removes_its_temporary(tmp_path):
    path = tmp_path / 'a.yaml'
    path.write_text('old\n')
    with pytest.raises(TypeError):
        files.write_atomic(path, 12345)   # neither str nor bytes: the write fails half way
    assert path.read_text() == 'old\n' and os.listdir(tmp_path) == ['a.yaml']
