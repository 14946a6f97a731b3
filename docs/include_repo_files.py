"""Files of the repository outside ``docs/`` that belong in the site: the reports and the changelog.

A MkDocs hook (``hooks:`` in ``mkdocs.yml``): every file under ``reports/`` joins the site at
``reports/...`` (the Markdown reports as pages, their figures beside them), so that the
validation pages link ``reports/calibration.md``; ``CHANGELOG.md`` joins it as a page. They
stay where they are written; nothing is copied into ``docs/``.
"""

from __future__ import annotations

import pathlib

from mkdocs.structure.files import File, InclusionLevel

REPORTS = "reports"
PAGES = ("CHANGELOG.md",)


def _file(root, path, config, inclusion=InclusionLevel.UNDEFINED):
    """A site file for ``path`` (relative to the repository's root ``root``)."""
    return File(
        path,
        src_dir=str(root),
        dest_dir=config["site_dir"],
        use_directory_urls=config["use_directory_urls"],
        inclusion=inclusion,
    )


def on_files(files, config, **kwargs):
    """MkDocs hook: add ``reports/**`` and ``CHANGELOG.md`` to the site's files."""
    root = pathlib.Path(config["config_file_path"]).resolve().parent
    for path in sorted((root / REPORTS).rglob("*")):
        if path.is_file() and not path.name.startswith("."):
            # linked from the validation page, not listed in the navigation
            relative = path.relative_to(root).as_posix()
            files.append(_file(root, relative, config, InclusionLevel.NOT_IN_NAV))
    for name in PAGES:
        files.append(_file(root, name, config))
    return files
