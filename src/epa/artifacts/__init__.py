"""A case folder on disk: file formats (``files``), the folder's paths, typed readers and writers and
failure markers (``case``)."""

__all__ = ["case", "files"]
