"""Where the viewer's image of an id comes from (the image-source policy of every viewer route): an EXR its
caller dropped into the viewer (``POST /v1/images``, kept in memory for its uploader), a finished job's
``image.exr``, or a running job's finished chunks merged into a partial image (issue 6: "where partial
results exist"; a noise-target job replaces its one partial after each round). A job with no image yet is a
conflict (409); another owner's job or upload is missing (404)."""

from __future__ import annotations

from hgcore.jobs.lifecycle import JobNotFoundError
from hgcore.jobs.status import JobStatus
from hgcore.store.base import ArtifactNotFoundError, ArtifactStore
from service.auth import Principal
from service.jobs import JobConflictError, JobService
from service.viewer_data import DecodedImage, DecodedImageCache, UploadedImages


class ViewerImages:
    """The decoded images the viewer routes read: an LRU cache of job images (``max_images``) and the
    last ``max_uploads`` uploaded EXRs."""

    def __init__(self, jobs: JobService, store: ArtifactStore, max_images: int = 8, max_uploads: int = 4):
        self.jobs = jobs
        self.cache = DecodedImageCache(store, max_images)
        self.uploads = UploadedImages(max_uploads)

    def is_upload(self, image_id: str, principal: Principal) -> bool:
        return self.uploads.get(image_id, principal.can_see) is not None

    def upload(self, owner: str, image: DecodedImage) -> str:
        """Keep an uploaded image for ``owner``; its id (usable wherever a job id is)."""
        return self.uploads.add(owner, image)

    def image(self, image_id: str, principal: Principal) -> DecodedImage:
        """The image of an upload or job ``image_id`` as ``principal`` may see it (decodes: call it off
        the event loop)."""
        uploaded = self.uploads.get(image_id, principal.can_see)
        if uploaded is not None:
            return uploaded
        view = self.jobs.get(image_id)
        if view is None or not principal.can_see(view.owner):
            raise JobNotFoundError(image_id)
        if view.status == JobStatus.SUCCEEDED:
            return self.cache.get(image_id)
        if view.status == JobStatus.RUNNING:
            film = self.jobs.scene(image_id)["film"]  # validated: every field present
            # A noise-target job replaces its one partial after each round: the round count tells them apart.
            revision = len(view.noise_target.rounds or []) if view.noise_target is not None else 0
            try:
                return self.cache.get_partial(image_id, film, revision)
            except ArtifactNotFoundError:
                pass
        raise JobConflictError(
            f"job_id: job {image_id} is {view.status.value}; its image exists once a chunk has finished"
        )
