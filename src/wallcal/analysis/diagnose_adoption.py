"""The adoption rule of ``wallcal diagnose`` (:mod:`wallcal.analysis.diagnose`): forward selection of the
extensions by their criterion, ties, and the weak rule for a structure that holds parameters at its bounds.
"""

from __future__ import annotations

#: BIC decrease needed to adopt an extension (Kass and Raftery: > 10 is very strong evidence)
ADOPT_DELTA = 10.0
#: BIC decrease that suffices while the structure adopted so far is rejected by its own optimum - one of the study's
#: parameters held at a bound of its prior box (Kass and Raftery: > 2 is "positive" evidence) - and the candidate
#: frees it (see :func:`forward_select`)
WEAK_DELTA = 2.0
#: a parameter whose optimum lies within this share of its range from a bound is held at that bound
BOUND_BAND = 0.005
#: extensions whose criterion lies within this of the best one's are tied: adopted together (Kass and Raftery:
#: a BIC difference below 2 is "not worth more than a bare mention")
TIE_DELTA = 2.0
#: candidates whose criterion lies within this of a step's best are fitted to convergence before they are compared
POLISH_MARGIN = 25.0
#: after the single candidates, each forward step tries the best few useful ones only
MAX_TRIALS = 3
#: on held-out evidence, each forward step tries at most this many of the promising extensions (those whose own fit
#: predicts the held-out window better than the base structure), best first
HELD_OUT_TRIALS = 6
#: most extensions adopted together
MAX_ADOPTED = 4


def held_at_bounds(space, x, names=None, band: float = BOUND_BAND) -> frozenset:
    """The parameters of ``space`` (those in ``names``; default all) whose value in ``x`` [SI] lies within
    ``band`` of its range from a bound of the prior box, in the space's unit coordinates."""
    sides = space.bound_sides(x, band)
    return frozenset(n for n, side in zip(space.names, sides, strict=True) if side and (names is None or n in names))


def forward_select(
    base,
    singles: dict,
    score,
    polish,
    compatible,
    max_adopted: int = MAX_ADOPTED,
    held=None,
    accept=None,
    rank=None,
):
    """Forward selection of extensions by the criterion (the ``bic`` of each fit; lower is better).

    The best single candidate is adopted when it lowers the criterion by at least :data:`ADOPT_DELTA`; then the
    :data:`MAX_TRIALS` best remaining useful candidates (those better than ``base`` alone) are each added to the
    adopted set, and so on, at most ``max_adopted`` extensions. At each step the candidates within
    :data:`POLISH_MARGIN` of the step's best are polished (fitted to convergence) before they are compared, and
    those that end within :data:`TIE_DELTA` of the best are tied: adopted together with it when the set still
    lowers the criterion by the step's threshold (the data cannot choose between them).

    A structure whose optimum holds one of the study's parameters at a bound of its prior box (``held``) fails
    its own check: its parameters compensate for what it lacks, so it is no plausible null, and the strong
    evidence that protects a plausible one does not apply. While it holds some, a step in which no candidate
    reaches :data:`ADOPT_DELTA` adopts the best candidate that lowers the criterion by at least
    :data:`WEAK_DELTA` and frees at least one of them (its optimum leaves it inside the box).

    Parameters
    ----------
    base : fit
        The study's structure: attributes ``names`` (an empty tuple) and ``bic``.
    singles : dict
        Extension name -> its fit alone (attributes ``names``, ``bic``).
    score : callable
        ``score(names, warm) -> fit`` of a set of extensions, warm-started at the fit ``warm``.
    polish : callable
        ``polish(fit) -> fit`` continued to convergence.
    compatible : callable
        ``compatible(names) -> bool``: whether the extensions can be adopted together.
    max_adopted : int
    held : callable, optional
        ``held(fit) -> frozenset`` of the study's parameters held at a bound at the fit's optimum. None: the
        strong threshold only.
    accept : callable, optional
        ``accept(fit, current) -> bool``: whether a fit may replace the structure adopted so far beyond its
        criterion (``diagnose``: its new values inside their plausible ranges and off their bounds, and a lower
        held-out RMSE of every temperature target). A step adopts only from the fits it accepts.
    rank : callable, optional
        ``rank(fit) -> float``, the held-out score (lower is better) when the study has a validation window. The
        held-out evidence then decides: every candidate is tried (the in-sample criterion may be blind to it),
        a step adopts the accepted fit of the lowest rank, provided the criterion does not reject it strongly
        (it rises by less than :data:`ADOPT_DELTA`); each later step tries the :data:`HELD_OUT_TRIALS` best
        promising extensions (their own fit predicts the window better than ``base``); no weak rule and no ties.

    Returns
    -------
    (fit, adopted, tied, weak)
        The adopted set's fit, its names, the tied groups as (names, criterion change against the best one
        alone), and the steps taken on the weaker threshold as (names adopted, criterion change of the step,
        parameters held before, parameters held after).
    """
    if rank is not None:
        return _select_held_out(base, singles, score, compatible, max_adopted, accept, rank)
    useful = [n for n, f in sorted(singles.items(), key=lambda kv: kv[1].bic) if f.bic < base.bic]
    current = base
    adopted: tuple = ()
    tied: list = []
    weak: list = []
    while len(adopted) < max_adopted:
        if not adopted:
            trials = [singles[n] for n in useful]
        else:
            pool = [n for n in useful if n not in adopted and compatible(adopted + (n,))][:MAX_TRIALS]
            trials = [score(adopted + (n,), current) for n in pool]
        if not trials:
            break
        # the close contenders are fitted to convergence before they are compared: a probe depth or a contact
        # link moves slowly in a few Jacobians, and the ranking of near-equals must not depend on that
        first = min(f.bic for f in trials)
        trials = [polish(f) if f.bic <= first + POLISH_MARGIN else f for f in trials]
        if accept is not None:
            trials = [f for f in trials if accept(f, current)]
            if not trials:
                break
        best = min(trials, key=lambda f: f.bic)
        threshold = ADOPT_DELTA
        before = frozenset() if held is None else held(current)
        if best.bic > current.bic - ADOPT_DELTA:
            # the structure so far fails its own check (parameters held at bounds): positive evidence suffices for
            # a candidate that frees some of them
            freeing = [f for f in trials if f.bic <= current.bic - WEAK_DELTA and before - held(f)] if before else []
            if not freeing:
                break
            best = min(freeing, key=lambda f: f.bic)
            threshold = WEAK_DELTA
        # extensions that explain the misfit as well as the best one (within TIE_DELTA): the data cannot choose
        # between them, so all are adopted and the posterior averages over them, rather than being conditional on
        # an arbitrary choice
        new = [n for n in best.names if n not in adopted]
        ties = [
            n
            for f in sorted(trials, key=lambda f: f.bic)
            if f is not best and f.bic <= best.bic + TIE_DELTA
            for n in f.names
            if n not in adopted and n not in new
        ]
        ties = [n for n in dict.fromkeys(ties) if compatible(tuple(best.names) + (n,))]
        if ties and len(best.names) + len(ties) <= max_adopted:
            both = score(tuple(best.names) + tuple(ties), best)
            ok = accept is None or accept(both, current)
            if ok and both.bic <= current.bic - threshold and (threshold == ADOPT_DELTA or before - held(both)):
                tied.append((new + ties, both.bic - best.bic))
                new = new + ties
                best = both
        if threshold != ADOPT_DELTA:
            weak.append((new, best.bic - current.bic, before, held(best)))
        current = best
        adopted = tuple(best.names)
    return current, adopted, tied, weak


def _select_held_out(base, singles, score, compatible, max_adopted, accept, rank):
    """Forward selection on held-out evidence (see :func:`forward_select`, ``rank``)."""
    order = [n for n, _ in sorted(singles.items(), key=lambda kv: rank(kv[1]))]
    # worth combining: the extensions whose own fit predicts the held-out window better than the base structure
    promising = [n for n in order if rank(singles[n]) < rank(base)]
    current = base
    adopted: tuple = ()
    while len(adopted) < max_adopted:
        if not adopted:
            trials = [singles[n] for n in order]
        else:
            pool = [n for n in promising if n not in adopted and compatible(adopted + (n,))][:HELD_OUT_TRIALS]
            trials = [score(adopted + (n,), current) for n in pool]
        trials = [f for f in trials if f.bic < current.bic + ADOPT_DELTA and (accept is None or accept(f, current))]
        if not trials:
            break
        current = min(trials, key=rank)
        adopted = tuple(current.names)
    return current, adopted, [], []
