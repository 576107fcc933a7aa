"""FMI both ways: FMUs as components (``fmu``), components as FMUs (``orchestrator export-fmu``)."""
