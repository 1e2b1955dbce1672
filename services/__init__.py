"""sctd services: learner, recorder, input clients."""
