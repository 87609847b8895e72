"""The pipeline stages: plan → render → postprocess → infer → aggregate (→ report)."""
