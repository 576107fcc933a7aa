"""python -m orchestrator.config --docs: the config tables of docs/design.md, from the schema."""

import sys

from orchestrator.config.schema import write_docs

if sys.argv[1:] != ["--docs"]:
    raise SystemExit("usage: python -m orchestrator.config --docs   (writes the config tables into docs/design.md)")
write_docs()
