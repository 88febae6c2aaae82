"""The physics-informed neural state-space (NSS) vehicle model: model, losses, training."""
