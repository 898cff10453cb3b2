"""The package's version, in a module of its own: what records it (params.json, batch.jsonl) imports it without
importing the package's top level, whose ``load_fit`` reaches back into ``deface.export``."""

__version__ = "0.1.0"
