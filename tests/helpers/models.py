"""A tiny classifier with a built-in tie, for the ONNX Runtime tests."""

from __future__ import annotations


def tied_model():
    """A small classifier whose classes 0 and 1 always tie, at the top (same weights, larger bias)."""
    import torch

    from sweep3d.stages.infer import Classifier, Preprocess

    torch.manual_seed(0)
    head = torch.nn.Linear(4, 6)
    with torch.no_grad():
        head.weight[1] = head.weight[0]
        head.bias[:2] = 10.0
    module = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3, stride=4), torch.nn.ReLU(), torch.nn.AdaptiveAvgPool2d(1),
                                 torch.nn.Flatten(), head).eval()
    return Classifier(module, Preprocess(resize=32, crop=32), labels=[f"c{i}" for i in range(6)])
