"""Captions tied to the drawn shape parameters (docs/method.md §1, the attribute corpus).

A shape is described by its family's nouns, graded attributes ``u in [0, 1]`` (the drawn
parameter's position in its range: thickness, length, height, ...) and part counts (legs,
arms, ...). A grade below ``LOW`` earns the attribute's low word ("thin"), above ``HIGH`` its
high word ("thick"), in between no word: a caption never states what the shape is not.

Phrasings are split: the ``train`` captions use ``TEMPLATES``, ``ADJECTIVES`` and the count
phrasings of ``WITH``; the ``heldout`` phrasings (``HELDOUT_TEMPLATES``, ``HELDOUT_ADJECTIVES``,
``HELDOUT_WITH``) and each family's held-out attribute pair (:func:`heldout_pair`) never occur
in a training caption, so a model card can test paraphrases and unseen combinations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LOW, HIGH = 1 / 3, 2 / 3
ORDER = ("length", "height", "width", "thickness", "roundness", "taper", "curve")
ADJECTIVES = {  # attribute: (low words, high words)
    "length": (("short", "stubby"), ("long", "elongated")),
    "height": (("flat", "low"), ("tall", "high")),
    "width": (("narrow",), ("wide", "broad")),
    "thickness": (("thin", "slender"), ("thick", "chunky")),
    "roundness": (("boxy", "angular"), ("round", "rounded")),
    "taper": ((), ("tapered", "pointed")),
    "curve": (("straight",), ("curved", "bent")),
}
HELDOUT_ADJECTIVES = {
    "length": (("stumpy",), ("lengthy",)), "height": (("squat",), ("towering",)),
    "width": (("slim",), ("broad-shouldered",)), "thickness": (("skinny",), ("fat",)),
    "roundness": (("square-edged",), ("smooth",)), "taper": ((), ("narrowing",)),
    "curve": (("unbent",), ("arched",)),
}
NUMBERS = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five", 6: "six", 7: "seven",
           8: "eight", 9: "nine", 10: "ten"}
SINGULAR = {"legs": "leg", "arms": "arm", "fins": "fin", "prongs": "prong", "teeth": "tooth",
            "tentacles": "tentacle", "segments": "segment", "steps": "step", "sides": "side",
            "points": "point", "turns": "turn", "fingers": "finger", "holes": "hole",
            "lumps": "lump", "spikes": "spike"}
WITH = ("with {n} {part}", "that has {n} {part}", "on {n} {part}")
HELDOUT_WITH = ("having {n} {part}", "carrying {n} {part}")
TEMPLATES = (
    "{np}", "{np} robot", "a soft robot shaped like {np}", "a 3D model of {np}",
    "a soft {bare}", "a robot in the shape of {np}", "{np} made of soft silicone",
    "a design that looks like {np}", "{bare}",
)
HELDOUT_TEMPLATES = ("something resembling {np}", "an elastic {bare}",
                     "a squishy robot that resembles {np}")
SPLIT_OF = {"train": "train", "reference": "train", "test": "train", "heldout": "heldout"}


@dataclass(frozen=True)
class Phrasing:
    """The training phrasings of a corpus version: templates, adjectives and the probability
    that a caption says an optional part count. Corpus 2 says every count; corpus 3 drops
    the count of families whose noun alone names them ("a spring") half of the time, and adds
    templates and adjectives near the held-out ones (the held-out words stay held out)."""

    templates: tuple[str, ...] = TEMPLATES
    adjectives: dict = field(default_factory=lambda: ADJECTIVES)
    p_count: float = 1.0


V2 = Phrasing()
V3 = Phrasing(
    templates=TEMPLATES + ("a flexible {bare}", "a rubber {bare}", "something like {np}",
                           "a soft robot that looks like {np}", "an object shaped like {np}"),
    adjectives={**ADJECTIVES,
                "length": (("short", "stubby", "compact"), ("long", "elongated")),
                "height": (("flat", "low", "shallow"), ("tall", "high", "lofty")),
                "thickness": (("thin", "slender", "lean"), ("thick", "chunky", "stout", "bulky")),
                "width": (("narrow",), ("wide", "broad", "spread-out"))},
    p_count=0.5)


@dataclass
class Description:
    """What a drawn shape is: family nouns (the first is canonical), graded attributes
    ``u in [0, 1]`` and part counts. ``on`` counts read "on N legs" (standing on them)."""

    nouns: tuple[str, ...]
    grades: dict[str, float] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    heldout_nouns: tuple[str, ...] = ()
    count_optional: bool = False  # the noun alone names the family (corpus 3 may omit it)

    def words(self) -> dict[str, str]:
        """Attribute -> "low" or "high" for the grades outside the middle third."""
        out = {}
        for a, u in self.grades.items():
            if a not in ADJECTIVES:
                raise ValueError(f"unknown attribute {a!r}")
            if u < LOW and ADJECTIVES[a][0]:
                out[a] = "low"
            elif u > HIGH:
                out[a] = "high"
        return out


def count_phrase(desc: Description) -> str | None:
    """The training phrase of the first part count ("with four legs"), or None."""
    if not desc.counts:
        return None
    part, k = next(iter(desc.counts.items()))
    return WITH[0].format(n=NUMBERS[k], part=part if k != 1 else SINGULAR[part])


def heldout_pair(desc: Description) -> tuple[str, str] | None:
    """The two attributes whose words never appear together in a training caption of this
    family: the first two graded ones in ``ORDER`` (None with fewer than two)."""
    attrs = [a for a in ORDER if a in desc.grades]
    return (attrs[0], attrs[1]) if len(attrs) >= 2 else None


def article(phrase: str) -> str:
    """``a`` or ``an`` for ``phrase`` (by sound: "an egg", "an L shape", "a U shape")."""
    first = phrase.split()[0]
    if first[0].isupper() and (len(first) == 1 or first[1] == "-"):  # a letter: its sound
        return "an" if first[0] in "AEFHILMNORSX" else "a"
    return "an" if first[0].lower() in "aeio" else "a"


def noun_phrase(noun: str, adjectives: list[str], count: str | None) -> tuple[str, str]:
    """``(np, bare)``: the phrase with and without its article."""
    bare = " ".join([*adjectives, noun]) + (f" {count}" if count else "")
    return f"{article(bare)} {bare}", bare


def caption(desc: Description, rng: np.random.Generator, split: str = "train",
            p_mention: float = 0.75, phrasing: Phrasing = V2) -> str:
    """One caption of ``desc``: a random noun, each worded attribute mentioned with
    probability ``p_mention`` (a random synonym), the counts (an optional one with
    ``phrasing.p_count``), in a random template of the split's phrasings."""
    held = SPLIT_OF[split] == "heldout"
    nouns = desc.nouns + (desc.heldout_nouns if held else ())
    noun = nouns[rng.integers(len(nouns))]
    words = desc.words()
    chosen = [a for a in ORDER if a in words and rng.uniform() < p_mention]
    pair = heldout_pair(desc)
    if not held and pair and pair[0] in chosen and pair[1] in chosen:
        chosen.remove(pair[int(rng.integers(2))])
    adjs = []
    for a in chosen:
        table = HELDOUT_ADJECTIVES if held and rng.uniform() < 0.5 else phrasing.adjectives
        opts = table[a][0 if words[a] == "low" else 1] or ADJECTIVES[a][1]
        adjs.append(opts[rng.integers(len(opts))])
    count = None
    said = bool(desc.counts)
    if said and desc.count_optional and phrasing.p_count < 1:
        said = bool(rng.uniform() < phrasing.p_count)
    if said:
        part, n = next(iter(desc.counts.items()))
        forms = HELDOUT_WITH if held and rng.uniform() < 0.5 else WITH
        form = forms[rng.integers(len(forms))]
        if form.startswith("on") and part != "legs":
            form = forms[0]
        count = form.format(n=NUMBERS[n], part=part if n != 1 else SINGULAR[part])
    np_, bare = noun_phrase(noun, adjs, count)
    templates = HELDOUT_TEMPLATES if held else phrasing.templates
    if count:  # "a block with two legs robot" is no phrase
        templates = tuple(t for t in templates if not t.endswith("} robot"))
    return templates[rng.integers(len(templates))].format(np=np_, bare=bare)


def captions(desc: Description, rng: np.random.Generator, n: int,
             split: str = "train", phrasing: Phrasing = V2) -> list[str]:
    """``n`` distinct captions of ``desc`` (fewer when the phrasings run out), canonical
    first: the plain noun phrase with every worded attribute and the counts."""
    words = desc.words()
    pair = heldout_pair(desc)
    canon_attrs = [a for a in ORDER if a in words]
    if SPLIT_OF[split] == "train" and pair and pair[0] in words and pair[1] in words:
        canon_attrs.remove(pair[1])
    adjs = [ADJECTIVES[a][0 if words[a] == "low" else 1][0] for a in canon_attrs]
    out = [noun_phrase(desc.nouns[0], adjs, count_phrase(desc))[0]]
    for _ in range(8 * n):
        if len(out) >= n:
            break
        c = caption(desc, rng, split, phrasing=phrasing)
        if c not in out:
            out.append(c)
    return out
