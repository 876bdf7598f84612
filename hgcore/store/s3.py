"""S3-compatible artifact store (boto3) for deployments whose workers run on several machines.

A single ``PutObject`` is atomic in S3 (an object is visible complete or not at all), so writes need no
temporary keys; a retried chunk's upload simply replaces the object under the same key.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import boto3
from botocore.exceptions import ClientError

from hgcore.errors import InputError
from hgcore.store.base import ArtifactInfo, ArtifactNotFoundError, ArtifactStore, validate_key


class S3Store(ArtifactStore):
    """Objects are ``s3://<bucket>/<prefix><key>``."""

    def __init__(
        self,
        bucket: str,
        prefix: str = "",
        endpoint_url: str | None = None,
        region: str = "us-east-1",
        client: Any | None = None,
    ) -> None:
        if not bucket:
            raise InputError("bucket: must be a non-empty S3 bucket name")
        self.bucket = bucket
        self.prefix = prefix.strip("/") + "/" if prefix.strip("/") else ""
        self.client = client or boto3.client("s3", endpoint_url=endpoint_url, region_name=region)

    def _object_key(self, key: str) -> str:
        return self.prefix + validate_key(key)

    def put_bytes(self, key: str, data: bytes) -> None:
        self.client.put_object(Bucket=self.bucket, Key=self._object_key(key), Body=data)

    def put_file(self, key: str, path: Path) -> None:
        # upload_file switches to multipart for large files; S3 publishes the object only on completion.
        self.client.upload_file(str(path), self.bucket, self._object_key(key))

    def iter_bytes(self, key: str, chunk_bytes: int = 1 << 20) -> Iterator[bytes]:
        try:
            response = self.client.get_object(Bucket=self.bucket, Key=self._object_key(key))
        except ClientError as error:
            if error.response.get("Error", {}).get("Code") in {"NoSuchKey", "404"}:
                raise ArtifactNotFoundError(key) from None
            raise
        body = response["Body"]
        try:
            yield from body.iter_chunks(chunk_bytes)
        finally:
            body.close()

    def list(self, prefix: str) -> list[ArtifactInfo]:
        object_prefix = self.prefix + prefix
        paginator = self.client.get_paginator("list_objects_v2")
        infos = [
            ArtifactInfo(item["Key"][len(self.prefix) :], int(item["Size"]))
            for page in paginator.paginate(Bucket=self.bucket, Prefix=object_prefix)
            for item in page.get("Contents", [])
        ]
        if not prefix.endswith("/"):  # a bare key or folder name: exact key or keys inside the folder
            infos = [i for i in infos if i.key == prefix or i.key.startswith(prefix + "/")]
        return sorted(infos, key=lambda info: info.key)

    def delete_prefix(self, prefix: str) -> int:
        keys = [self.prefix + info.key for info in self.list(prefix)]
        for start in range(0, len(keys), 1000):  # DeleteObjects takes at most 1000 keys
            batch = [{"Key": k} for k in keys[start : start + 1000]]
            self.client.delete_objects(Bucket=self.bucket, Delete={"Objects": batch, "Quiet": True})
        return len(keys)

    def ping(self) -> None:
        self.client.head_bucket(Bucket=self.bucket)
