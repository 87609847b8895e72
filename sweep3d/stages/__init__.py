"""The stages that compute: plan, render, postprocess and infer, each owning its plug-ins."""
