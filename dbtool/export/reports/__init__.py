"""What an export tells its reader: the fabrication checks and ``report.json``/``report.md``,
the assembly sheet (``assembly.md``, ``exploded.png``, ``section.png``) and ``tendons.png``."""
