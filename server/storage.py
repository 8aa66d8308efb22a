"""The artifact store: run recordings, meshes and logs, in a local folder or an S3 bucket.

Keys are relative paths like ``runs/12/recording.npz``. Every `put` returns the size and the
SHA-256 of what was stored; a store that cannot take the file raises `ArtifactStoreError`.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol
from urllib.parse import unquote, urlparse

if TYPE_CHECKING:
    from server.settings import Settings


class ArtifactStoreError(RuntimeError):
    """The store failed to take or give back an artifact (full, unreachable, missing)."""


@dataclass(frozen=True)
class StoredArtifact:
    location: str
    size_bytes: int
    sha256: str


class ArtifactStore(Protocol):
    def put(self, key: str, source: Path) -> StoredArtifact: ...

    def open_path(self, location: str) -> Path:
        """A local file with the artifact's content (downloaded first if remote)."""
        ...


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_key(key: str) -> None:
    parts = Path(key).parts
    if not parts or Path(key).is_absolute() or ".." in parts:
        raise ArtifactStoreError(f"invalid artifact key {key!r}")


class LocalArtifactStore:
    """Files under one folder, written atomically (temporary file, then rename)."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def put(self, key: str, source: Path) -> StoredArtifact:
        _check_key(key)
        target = self.root / key
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".part-", dir=target.parent)
            os.close(fd)
            try:
                shutil.copyfile(source, tmp)
                os.replace(tmp, target)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except OSError as exc:
            raise ArtifactStoreError(f"artifact store {self.root} failed to store {key}: "
                                     f"{exc.strerror or exc}") from exc
        return StoredArtifact(key, target.stat().st_size, _sha256(target))

    def open_path(self, location: str) -> Path:
        _check_key(location)
        path = self.root / location
        if not path.is_file():
            raise ArtifactStoreError(f"artifact {location} is missing from the store")
        return path


class S3ArtifactStore:
    """An S3-compatible bucket (AWS, MinIO, ...), through boto3 (`pip install flybo[s3]`)."""

    def __init__(self, bucket: str, prefix: str, endpoint_url: str | None,
                 cache_dir: Path) -> None:
        try:
            import boto3
        except ImportError as exc:  # an optional dependency
            raise ArtifactStoreError("s3:// artifact stores need boto3: pip install "
                                     "'flybo[s3]'") from exc
        self.client: Any = boto3.client("s3", endpoint_url=endpoint_url)
        self.bucket, self.prefix, self.cache_dir = bucket, prefix.strip("/"), cache_dir

    def _object(self, key: str) -> str:
        return f"{self.prefix}/{key}" if self.prefix else key

    def put(self, key: str, source: Path) -> StoredArtifact:
        _check_key(key)
        try:
            self.client.upload_file(str(source), self.bucket, self._object(key))
        except Exception as exc:  # boto3 raises many unrelated types
            raise ArtifactStoreError(f"s3 bucket {self.bucket} failed to store {key}: "
                                     f"{exc}") from exc
        return StoredArtifact(key, source.stat().st_size, _sha256(source))

    def open_path(self, location: str) -> Path:
        _check_key(location)
        local = self.cache_dir / location
        if not local.is_file():
            local.parent.mkdir(parents=True, exist_ok=True)
            try:
                self.client.download_file(self.bucket, self._object(location), str(local))
            except Exception as exc:
                raise ArtifactStoreError(f"artifact {location} is missing from bucket "
                                         f"{self.bucket}: {exc}") from exc
        return local


def open_store(url: str, *, endpoint_url: str | None = None,
               cache_dir: Path | None = None) -> ArtifactStore:
    """The store behind `url`: ``file:///abs/folder`` or ``s3://bucket/prefix``."""
    parsed = urlparse(url)
    if parsed.scheme == "file":
        return LocalArtifactStore(Path(unquote(parsed.path)))
    if parsed.scheme == "s3":
        cache = cache_dir or Path(tempfile.gettempdir()) / "flybo-artifacts"
        return S3ArtifactStore(parsed.netloc, parsed.path, endpoint_url, cache)
    raise ArtifactStoreError(f"unsupported artifact store URL {url!r}: use file:// or s3://")


def settings_store(settings: Settings) -> ArtifactStore:
    """The store `settings` name, with its S3 endpoint and local cache folder."""
    return open_store(settings.artifacts, endpoint_url=settings.s3_endpoint_url,
                      cache_dir=settings.artifact_cache_dir)
