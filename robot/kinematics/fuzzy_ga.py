"""Antecedent tuning of the Sugeno IK system by a genetic algorithm (chapter section 3.6.3.2).

As the chapter describes it:

* 20 tuning points: the mean and the standard deviation of the 10 MFs (5 inputs x Low/High),
  gene ``4 i + 0, 1, 2, 3`` = (Low mean, Low sigma, High mean, High sigma) of input ``i``;
* each varied within +-33 % of its initial value.  The chapter's example (the Low mean of
  ``x`` varied between -1.7373 and -0.8686 m, i.e. -1.30295 m times 4/3 and 2/3) shows the
  fraction is one third, which :attr:`GAConfig.variation` uses.  A gene whose initial value
  is zero (a universe ending at 0) would have no range; it is varied by one third of its MF's
  sigma instead;
* 10 bits per gene, a 200-bit string per individual, decoded linearly
  ``v = lo + (hi - lo) g / (2^10 - 1)`` with ``g`` the gene read most significant bit first;
* a population of 20 strings drawn at random, roulette-wheel selection (Jang, Sun and
  Mizutani 1997, section 7.3; Goldberg 1989), single-point crossover with probability 0.95
  per pair, bit-flip mutation with probability 0.01 per bit, generational replacement;
* seeded: the chapter used Knuth's random number generator; this uses NumPy's seeded
  ``Generator`` (PCG64), so runs are reproducible but not bit-identical to the chapter's.

Choices the chapter leaves open, made here:

* fitness ``1 / E``, with ``E`` the SSE (eq. 23) over the training poses after the
  consequents are re-tuned by gradient descent (:func:`~robot.kinematics.fuzzy.tune_consequents`,
  from the same initial consequents) for each individual, since the consequents that suit one
  set of MFs do not suit another;
* no elitism (the chapter names none), but the best individual seen in any generation is
  kept and returned.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.kinematics.fuzzy import SugenoIK, sse, tune_consequents

__all__ = [
    "GAConfig",
    "GATuning",
    "crossover",
    "decode",
    "gene_ranges",
    "mutate",
    "roulette_wheel",
    "tune_antecedents",
]

N_GENES = 20


@dataclass(frozen=True)
class GAConfig:
    """Settings of the genetic algorithm (defaults: the chapter's values).

    Attributes
    ----------
    population_size : int
        Strings per generation (chapter: 20; must be even for pairing).
    bits_per_gene : int
        Bits per tuning point (chapter: 10).
    variation : float
        Half-width of each gene's range as a fraction of its initial value (chapter: 33 %,
        one third by its example).
    crossover_probability : float
        Per pair (chapter: 0.95).
    mutation_probability : float
        Per bit (chapter: 0.01).
    generations : int
        GA cycles (chapter: 50).
    consequent_epochs : int
        Gradient-descent epochs when re-tuning the consequents of each individual.
    seed : int
        Seed of the random generator.
    """

    population_size: int = 20
    bits_per_gene: int = 10
    variation: float = 1.0 / 3.0
    crossover_probability: float = 0.95
    mutation_probability: float = 0.01
    generations: int = 50
    consequent_epochs: int = 3000
    seed: int = 0

    def __post_init__(self) -> None:
        if self.population_size < 2 or self.population_size % 2:
            raise ValueError(f"population_size must be even and >= 2, got {self.population_size}")
        if not 1 <= self.bits_per_gene <= 30:
            raise ValueError(f"bits_per_gene must be in 1..30, got {self.bits_per_gene}")
        if not 0.0 < self.variation < 1.0:
            raise ValueError(f"variation must be in (0, 1), got {self.variation}")
        for name in ("crossover_probability", "mutation_probability"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v}")
        if self.generations < 0 or self.consequent_epochs < 0:
            raise ValueError("generations and consequent_epochs must be >= 0")


def _genes_of(fis: SugenoIK) -> NDArray[np.float64]:
    """The 20 tuning points of ``fis`` in gene order (Low mean, Low sigma, High mean, High sigma)."""
    return np.column_stack(
        [fis.mean[:, 0], fis.sigma[:, 0], fis.mean[:, 1], fis.sigma[:, 1]]
    ).ravel()


def _fis_of(genes: NDArray[np.float64], consequents: NDArray[np.float64]) -> SugenoIK:
    g = genes.reshape(5, 4)
    return SugenoIK(g[:, [0, 2]], g[:, [1, 3]], consequents)


def gene_ranges(
    fis0: SugenoIK, variation: float = 1.0 / 3.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lower and upper bounds (20,) of each gene: initial value +- ``variation`` of itself."""
    v0 = _genes_of(fis0)
    sig = np.repeat(fis0.sigma, 2, axis=1).ravel()  # the sigma of each gene's own MF
    scale = np.where(np.abs(v0) > 1e-9 * sig, np.abs(v0), sig)
    return v0 - variation * scale, v0 + variation * scale


def decode(
    bits: ArrayLike, lo: ArrayLike, hi: ArrayLike, bits_per_gene: int = 10
) -> NDArray[np.float64]:
    """Gene values of binary strings.

    Parameters
    ----------
    bits : array_like of {0, 1}, shape (M, G * bits_per_gene) or (G * bits_per_gene,)
    lo, hi : array_like of shape (G,)
        Gene ranges; all-zero bits decode to ``lo``, all-one bits to ``hi``.

    Returns
    -------
    ndarray of shape (M, G) (or (G,))
    """
    B = np.asarray(bits, dtype=np.int64)
    lo_a, hi_a = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    B2 = B.reshape(-1, B.shape[-1])
    G = lo_a.size
    if B2.shape[1] != G * bits_per_gene:
        raise ValueError(f"bits must have {G * bits_per_gene} columns, got {B2.shape[1]}")
    weights = 1 << np.arange(bits_per_gene - 1, -1, -1, dtype=np.int64)
    g = B2.reshape(-1, G, bits_per_gene) @ weights
    out = lo_a + (hi_a - lo_a) * (g / float((1 << bits_per_gene) - 1))
    return out[0] if B.ndim == 1 else out


def roulette_wheel(fitness: ArrayLike, n: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """Indices of ``n`` individuals drawn with probability ``fitness_i / sum(fitness)``.

    Each draw is a uniform point on the wheel ``[0, sum(fitness))`` located in the
    cumulative sums (fitness must be non-negative with a positive sum).
    """
    f = np.asarray(fitness, dtype=np.float64)
    if f.ndim != 1 or not np.all(f >= 0) or not f.sum() > 0:
        raise ValueError(f"fitness must be non-negative with a positive sum, got {f.tolist()}")
    edges = np.cumsum(f)
    idx = np.searchsorted(edges, rng.random(n) * edges[-1], side="right")
    return np.minimum(idx, f.size - 1)


def crossover(parents: ArrayLike, probability: float, rng: np.random.Generator) -> NDArray[np.int8]:
    """Single-point crossover of consecutive pairs (0, 1), (2, 3), ...

    With ``probability`` a pair swaps its tails after a cut drawn uniformly in
    ``1 .. L - 1``; otherwise both pass unchanged.
    """
    P = np.array(parents, dtype=np.int8)
    if P.ndim != 2 or P.shape[0] % 2:
        raise ValueError(f"parents must have shape (even M, L), got {P.shape}")
    L = P.shape[1]
    for k in range(0, P.shape[0], 2):
        if rng.random() < probability:
            cut = int(rng.integers(1, L))
            tail = P[k, cut:].copy()
            P[k, cut:] = P[k + 1, cut:]
            P[k + 1, cut:] = tail
    return P


def mutate(bits: ArrayLike, probability: float, rng: np.random.Generator) -> NDArray[np.int8]:
    """Flip each bit independently with ``probability``."""
    B = np.array(bits, dtype=np.int8)
    flip = rng.random(B.shape) < probability
    B[flip] ^= 1
    return B


@dataclass(frozen=True)
class GATuning:
    """Result of :func:`tune_antecedents`.

    Attributes
    ----------
    fis : SugenoIK
        The best system found: its MFs and its gradient-descent consequents.
    best_sse_history : ndarray of shape (generations + 1,)
        Best training SSE seen so far, after the initial population and each generation.
    mean_sse_history : ndarray of shape (generations + 1,)
        Mean SSE of each generation's population.
    evaluations : int
        Fitness evaluations (each a consequent re-tuning).
    config : GAConfig
    """

    fis: SugenoIK
    best_sse_history: NDArray[np.float64]
    mean_sse_history: NDArray[np.float64]
    evaluations: int
    config: GAConfig


def tune_antecedents(
    fis0: SugenoIK,
    poses: ArrayLike,
    q: ArrayLike,
    *,
    config: GAConfig | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> GATuning:
    """Tune the MFs of ``fis0`` by the chapter's genetic algorithm (module docstring).

    Parameters
    ----------
    fis0 : SugenoIK
        Initial system: its MFs are the centres of the gene ranges, its consequents the
        start of every consequent re-tuning.
    poses, q : array_like of shape (N, 5)
        Training inputs and target joints.
    config : GAConfig, optional
        Defaults to the chapter's settings.
    progress : callable ``(fraction, message)``, optional
        Called after each generation.
    """
    cfg = config or GAConfig()
    X = np.asarray(poses, dtype=np.float64)
    Q = np.asarray(q, dtype=np.float64)
    rng = np.random.default_rng(cfg.seed)
    lo, hi = gene_ranges(fis0, cfg.variation)
    n_bits = N_GENES * cfg.bits_per_gene
    pop = rng.integers(0, 2, size=(cfg.population_size, n_bits), dtype=np.int8)
    best_sse, best_fis = np.inf, fis0
    best_hist: list[float] = []
    mean_hist: list[float] = []
    evals = 0

    def evaluate(pop: NDArray[np.int8]) -> NDArray[np.float64]:
        nonlocal best_sse, best_fis, evals
        errs = np.empty(pop.shape[0])
        for i, genes in enumerate(decode(pop, lo, hi, cfg.bits_per_gene)):
            fit = tune_consequents(
                _fis_of(genes, fis0.consequents), X, Q, epochs=cfg.consequent_epochs
            )
            errs[i] = sse(fit.fis, X, Q)
            evals += 1
            if errs[i] < best_sse:
                best_sse, best_fis = errs[i], fit.fis
        best_hist.append(best_sse)
        mean_hist.append(float(errs.mean()))
        return errs

    errs = evaluate(pop)
    for gen in range(cfg.generations):
        fitness = 1.0 / np.maximum(errs, 1e-300)
        mating = pop[roulette_wheel(fitness, cfg.population_size, rng)]
        pop = mutate(
            crossover(mating, cfg.crossover_probability, rng), cfg.mutation_probability, rng
        )
        errs = evaluate(pop)
        if progress is not None:
            progress(
                (gen + 1) / cfg.generations,
                f"GA cycle {gen + 1}/{cfg.generations}: best SSE {best_sse:.4g}",
            )
    return GATuning(best_fis, np.array(best_hist), np.array(mean_hist), evals, cfg)
