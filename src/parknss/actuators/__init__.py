"""Per-channel actuator submodels, envelopes, two-phase selection and co-tuning (§III, §V-E)."""
