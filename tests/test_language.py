"""Prior selection by language: the default embedding, user files in every format, errors."""

import numpy as np
import pytest
from gensim.models import KeyedVectors

from sb3_disagree.priors.language import (NotEnoughPriorsError, UnknownWordError, detect_format, load_embedding,
                                   normalise_goal, select_priors)

LABELS = ["shower", "bathtub", "toilet", "bed", "wardrobe", "nightstand", "stove", "toaster", "microwave", "table"]


@pytest.fixture(scope="module")
def default_embedding():
    return load_embedding()


def test_default_embedding_picks_the_papers_priors(default_embedding):
    assert [l for l, _ in select_priors("bathtub", LABELS, default_embedding)] == ["shower", "toilet"]
    assert [l for l, _ in select_priors("nightstand", LABELS, default_embedding)] == ["bed", "wardrobe"]


def test_never_the_goals_own_entry_and_ties_by_label(default_embedding):
    chosen = select_priors("Bathtub", LABELS + ["bathtub"], default_embedding, k=3)
    assert "bathtub" not in [l for l, _ in chosen]
    sims = [s for _, s in chosen]
    assert sims == sorted(sims, reverse=True)


def test_vectors_are_cached(default_embedding):
    default_embedding.vectors(["bathtub", "shower"])
    assert default_embedding.cache_path.exists()
    with np.load(default_embedding.cache_path, allow_pickle=False) as cached:  # arrays: reading it runs nothing
        assert "bathtub" in list(cached["keys"]) and cached["vectors"].shape[1] == 384


def test_multi_word_goal_and_unknown_word(default_embedding):
    v = default_embedding.vectors(["coffee table"])
    assert v.shape == (1, 384) and np.isclose(np.linalg.norm(v), 1)
    with pytest.raises(UnknownWordError, match="xqzt"):
        default_embedding.vectors(["xqzt"])
    with pytest.raises(UnknownWordError) as info:
        default_embedding.vectors(["bathtubb"])
    assert "bathtub" in info.value.suggestions  # words seen before are suggested


def test_fewer_than_k_priors(default_embedding):
    with pytest.raises(NotEnoughPriorsError, match="only 1 compatible"):
        select_priors("bathtub", ["shower", "bathtub"], default_embedding)


WORDS = ["shower", "bathtub", "toilet", "bed", "coffee_table"]


@pytest.fixture()
def small_kv():
    rng = np.random.default_rng(0)
    kv = KeyedVectors(vector_size=6)
    kv.add_vectors(WORDS, rng.normal(size=(len(WORDS), 6)).astype(np.float32))
    return kv


@pytest.mark.parametrize("fmt,suffix,writer", [
    ("word2vec", ".txt", lambda kv, p: kv.save_word2vec_format(p, binary=False)),
    ("word2vec-binary", ".bin", lambda kv, p: kv.save_word2vec_format(p, binary=True)),
    ("glove", ".txt", lambda kv, p: _write_glove(kv, p)),
    ("keyedvectors", ".kv", lambda kv, p: kv.save(p)),
])
def test_user_embedding_formats(tmp_path, small_kv, fmt, suffix, writer):
    path = tmp_path / f"vectors{suffix}"
    writer(small_kv, str(path))
    assert detect_format(path) == fmt
    if fmt == "keyedvectors":  # a pickle: read only when trusted
        with pytest.raises(ValueError, match="--trust"):
            load_embedding(path)
    for given in ("auto", fmt):
        emb = load_embedding(path, format=given, trust=fmt == "keyedvectors")
        expected = small_kv["bathtub"] / np.linalg.norm(small_kv["bathtub"])
        assert np.allclose(emb.vectors(["bathtub"])[0], expected, atol=1e-5)
    # A multi-word goal uses the phrase's own token when the vectors have one.
    assert np.allclose(emb.vectors(["coffee table"])[0], small_kv["coffee_table"] / np.linalg.norm(small_kv["coffee_table"]),
                       atol=1e-5)
    # Otherwise the normalised mean of its words' unit vectors.
    u = [small_kv[w] / np.linalg.norm(small_kv[w]) for w in ("shower", "bed")]
    mean = np.mean(u, axis=0)
    assert np.allclose(emb.vectors(["shower bed"])[0], mean / np.linalg.norm(mean), atol=1e-5)
    with pytest.raises(UnknownWordError, match="sofa"):
        emb.vectors(["sofa"])
    with pytest.raises(UnknownWordError) as info:
        emb.vectors(["bathtubs"])
    assert info.value.suggestions[0] == "bathtub"


def _write_glove(kv, path):
    with open(path, "w") as f:
        for w in kv.index_to_key:
            f.write(w + " " + " ".join(f"{x:.6f}" for x in kv[w]) + "\n")


def test_fasttext_binary(tmp_path):
    from gensim.models import FastText
    from gensim.models.fasttext import save_facebook_model

    sentences = [["the", "shower", "and", "the", "bathtub"], ["a", "bed", "and", "a", "toilet"]] * 20
    model = FastText(sentences, vector_size=8, min_count=1, epochs=2, seed=0, workers=1)
    path = tmp_path / "vectors.bin"
    save_facebook_model(model, str(path))
    assert detect_format(path) == "fasttext"
    emb = load_embedding(path)
    v = emb.vectors(["shower", "showers"])  # fastText builds unseen words from character n-grams
    assert v.shape == (2, 8) and np.allclose(np.linalg.norm(v, axis=1), 1)


def test_bad_embedding_inputs(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_embedding(tmp_path / "missing.txt")
    bad = tmp_path / "bad.txt"
    bad.write_text("2 3\nshower 1 2\n")
    with pytest.raises(ValueError, match="could not read"):
        load_embedding(bad)
    with pytest.raises(ValueError, match="unknown embedding format"):
        load_embedding(bad, format="xml")


def test_normalise_goal():
    assert normalise_goal("  Coffee_Table ") == "coffee table"


def test_a_zero_vector_is_refused_rather_than_ranked_at_nan():
    from sb3_disagree.priors.language import KeyedVectorsEmbedding, rank_by_similarity

    kv = KeyedVectors(vector_size=3)
    kv.add_vectors(["bathtub", "shower", "toilet"], np.array([[1, 0, 0], [0, 0, 0], [0, 1, 0]], dtype=np.float32))
    with pytest.raises(ValueError, match="'shower' a zero or non-finite vector"):
        rank_by_similarity("bathtub", ["shower", "toilet"], KeyedVectorsEmbedding(kv))
