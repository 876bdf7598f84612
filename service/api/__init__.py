"""HTTP layer: dependencies and routers (thin; domain logic lives in ``service.jobs`` and friends)."""
