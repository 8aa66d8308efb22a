"""Apply the Alembic revisions in `migrations/` to a database, as the API does at start-up.

The revisions live in the repository's top-level `migrations/` folder; the wheel ships them
inside this package as `server/migrations/` (pyproject.toml maps the one onto the other), so
an installed `flybo` finds them without the source tree.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import Engine


def migrations_dir() -> Path:
    """The folder holding Alembic's `env.py` and `versions/`: inside the installed package, or
    the source tree's `migrations/` (a checkout, or an editable install)."""
    package = Path(str(files("server")))
    installed = package / "migrations"
    if (installed / "env.py").is_file():
        return installed
    # Only beside the project's own pyproject.toml: in site-packages a `migrations` folder
    # next to `server` would belong to another distribution.
    root = package.parent
    if (root / "pyproject.toml").is_file() and (root / "migrations" / "env.py").is_file():
        return root / "migrations"
    raise RuntimeError(
        f"the Alembic migrations are missing: neither {installed} nor a source tree's "
        f"migrations/ beside {package}; reinstall flybo"
    )


def alembic_config(url: str) -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(migrations_dir()).replace("%", "%%"))
    # ConfigParser interpolation would eat '%' in passwords.
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def upgrade(engine: Engine) -> None:
    """Bring the database of `engine` to the newest revision (no-op when it is there)."""
    cfg = alembic_config(engine.url.render_as_string(hide_password=False))
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "head")
