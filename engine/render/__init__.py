"""GPU-side helpers of the renderer: they hold GL resources and know nothing of the ECS."""
