#!/usr/bin/env bash
# The documentation: installs MkDocs if missing (Debian's package), regenerates the generated
# pages (docs/reference/scene.md from the parser, docs/benchmarks.md from scripts/results/),
# then builds the site with --strict (any warning, e.g. a broken link, fails).
# Usage: bash scripts/docs.sh [SITE_DIR]     (default: a temporary folder, removed at the end)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v mkdocs >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "docs: installing mkdocs (apt)"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends mkdocs >/dev/null
fi
PY=.venv/bin/python; [ -x "$PY" ] || PY=python3
$PY scripts/docs_reference.py
$PY scripts/docs_benchmarks.py
site="${1:-}"
if [ -z "$site" ]; then
  site=$(mktemp -d); trap 'rm -rf "$site"' EXIT
fi
mkdocs build --strict -q -d "$site"
echo "docs: built in $site"
