"""A case folder on disk: file formats (``files``), the stage list that lays the folder out and the
declaration a stage makes of itself (``stage``), the folder's paths, typed readers and writers,
failure markers and the typed view of its values (``case``)."""

__all__ = ["case", "files", "stage"]
