"""Dask worker plugins of the batch door (:func:`~bayes_roadload.analysis.batch.batch_client`),
in a module of their own: it imports ``distributed``, which the command line loads only when it
starts a cluster."""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin


class CompilationCachePlugin(WorkerPlugin):
    """Turns on JAX's persistent compilation cache in ``path`` when a worker starts
    (:func:`~bayes_roadload._jax.enable_compilation_cache`; its minimum compile time is read from
    the worker's environment, inherited from the process that started the cluster)."""

    name = "bayes-roadload-compilation-cache"

    def __init__(self, path: str):
        self.path = path

    def setup(self, worker) -> None:
        from .._jax import enable_compilation_cache

        enable_compilation_cache(self.path)
