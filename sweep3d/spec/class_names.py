"""One name per class: the name a spec gives each class its objects' labels name.

A model knows a class by one name (ImageNet's class 770 is ``sneaker``) and accepts several
(``running shoe``); results carry the name the *spec* used, so that a label written in the spec
finds its rows (``WHERE top1_label = 'running shoe'``). That needs one name per class: two
labels naming one class by different names are refused, as the spec's own contradiction
(spellings of one name are one name). A label given as an id names nothing: the model's name
stands for it.
"""

from __future__ import annotations

from typing import Sequence

from sweep3d.spec.catalogue import LabelSpace


class NameClash(ValueError):
    """Two labels of a spec name one class differently."""

    def __init__(self, key: str, problem: str) -> None:
        super().__init__(problem)
        self.key = key


def normal_name(text: str) -> str:
    """``text`` as class names are matched: lower case, ``-`` and ``_`` as spaces, spaces single."""
    return " ".join(text.lower().replace("_", " ").replace("-", " ").split())


def spec_class_names(objects: Sequence[Sequence[int | str]], classes: LabelSpace) -> dict[int, str]:
    """Class id → the name the spec's labels give it (``objects``: each object's labels, in spec
    order); labels given as ids, and names the model does not know, are left out (the caller
    reports unknown names). Spellings of one name (case, ``-``, ``_``, spaces: :func:`normal_name`)
    are one name, printed as first written.

    Raises:
        NameClash: naming ``objects[i].labels[j]``, the label that names an already named class
            by another name.
    """
    named: dict[int, tuple[str, str]] = {}
    for i, labels in enumerate(objects):
        for j, label in enumerate(labels):
            if not isinstance(label, str):
                continue
            try:
                class_id = classes.index(label)
            except ValueError:
                continue
            key = f"objects[{i}].labels[{j}]"
            name, first = named.setdefault(class_id, (label, key))
            if normal_name(name) != normal_name(label):
                raise NameClash(key, f"{label!r} is class {class_id}, which {first} calls {name!r}; results name "
                                     f"each class as the spec does, so the spec must name it once: write {name!r} "
                                     f"here too (or the class id {class_id})")
    return {class_id: name for class_id, (name, _) in named.items()}
