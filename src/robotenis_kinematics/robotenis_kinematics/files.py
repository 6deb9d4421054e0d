"""Writing a file so that nothing is ever half written."""
import os
import tempfile


def write_atomic(path, data):
    """
    Write ``data`` (str or bytes) to ``path``: a temporary file in the same folder, then rename.

    The temporary file is flushed to disk before the rename and removed if anything fails, so
    ``path`` holds either its old content or the whole new one.
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix='.tmp-', suffix=os.path.splitext(path)[1], dir=folder)
    try:
        with os.fdopen(fd, 'w' if isinstance(data, str) else 'wb') as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
