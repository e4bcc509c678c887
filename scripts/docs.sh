#!/usr/bin/env bash
# The documentation: sets up .venv (scripts/setup.sh) and installs MkDocs if missing,
# regenerates the generated pages (docs/reference/scene.md from the parser, docs/benchmarks.md
# from scripts/results/) and the pictures (docs/img/scenes/, scripts/render_docs.py), then
# builds the site with --strict (any warning, e.g. a broken link, fails) and checks every anchor.
# Usage: bash scripts/docs.sh [SITE_DIR]     (default: a temporary folder, removed at the end)
set -euo pipefail
site="${1:-}"
if [ -n "$site" ]; then   # relative to where the command runs; absolute for the anchor check
  mkdir -p "$site"; site=$(cd "$site" && pwd)
fi
cd "$(dirname "$0")/.."
if ! command -v mkdocs >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "docs: installing mkdocs (apt)"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends mkdocs >/dev/null
fi
# the project's .venv (parsolve importable, vtk for the pictures): a fresh clone gets it here
[ -x .venv/bin/python ] && .venv/bin/python -c "import parsolve, vtk" 2>/dev/null || bash scripts/setup.sh
PY=.venv/bin/python
$PY scripts/docs_reference.py
$PY scripts/docs_benchmarks.py
$PY scripts/render_docs.py   # the pictures of the shipped scenes (docs/img/scenes/)
if [ -z "$site" ]; then
  site=$(mktemp -d); trap 'rm -rf "$site"' EXIT
fi
mkdocs build --strict -q -d "$site"
# mkdocs 1.4 checks that linked pages exist, not their anchors: check every #anchor too.
$PY - "$site" <<'PYEOF'
import re, sys
from pathlib import Path
site = Path(sys.argv[1]).resolve(); bad = []
ids = {p: set(re.findall(r'id="([^"]+)"', p.read_text())) for p in site.rglob("*.html")}
for page, text in ((p, p.read_text()) for p in ids):
    for target, anchor in re.findall(r'href="([^"#:]*)#([^"]+)"', text):
        dest = (page.parent / target).resolve() if target else page
        dest = dest / "index.html" if dest.is_dir() else dest
        if anchor not in ids.get(dest, set()):
            bad.append(f"{page.relative_to(site)}: #{anchor} -> {target or '(same page)'}")
if bad:
    sys.exit("docs: broken anchors:\n  " + "\n  ".join(bad))
PYEOF
echo "docs: built in $site"
