import numpy as np
import pytest

from policy.action_tokenizer import ActionBounds, ActionTokenizer
from policy.vocab import VocabLayout


@pytest.mark.parametrize("bins", [64, 2048, 8192])
def test_roundtrip_within_half_a_bin(bins):
    layout = VocabLayout(action_bins=bins)
    tok = ActionTokenizer(bins=bins, token_offset=layout.action_offset)
    rng = np.random.default_rng(0)
    a = rng.uniform(tok.low, tok.high, size=(500, 7))
    back, tokens, n_clipped = tok.roundtrip(a)
    assert n_clipped == 0
    lo, hi = layout.range_of("action")
    assert tokens.min() >= lo and tokens.max() < hi
    assert np.all(np.abs(back - a) <= tok.bin_width / 2 + 1e-12)
    # bin centres decode to themselves
    assert np.array_equal(tok.encode(back)[0], tokens)


def test_out_of_range_is_clipped_and_counted_not_wrapped():
    tok = ActionTokenizer(bins=2048)
    a = np.array([[5.0, -5.0, 0.4, 0.0, 0.0, 0.0, 0.04]])
    back, tokens, n_clipped = tok.roundtrip(a)
    assert n_clipped == 2
    assert tokens[0, 0] == 2047 and tokens[0, 1] == 0
    assert back[0, 0] == pytest.approx(tok.high[0] - tok.bin_width[0] / 2)
    assert back[0, 1] == pytest.approx(tok.low[1] + tok.bin_width[1] / 2)


def test_bad_tokens_and_inputs_raise():
    tok = ActionTokenizer(bins=16, token_offset=100)
    with pytest.raises(ValueError, match="outside the action range"):
        tok.decode(np.full((1, 7), 99))
    with pytest.raises(ValueError, match="outside the action range"):
        tok.decode(np.full((1, 7), 116))
    with pytest.raises(TypeError):
        tok.decode(np.full((1, 7), 100.0))
    with pytest.raises(ValueError, match="shape"):
        tok.encode(np.zeros((3, 6)))
    with pytest.raises(ValueError, match="NaN"):
        tok.encode(np.full((1, 7), np.nan))
    with pytest.raises(ValueError, match="bins"):
        ActionTokenizer(bins=1)
    with pytest.raises(ValueError, match="low < high"):
        ActionBounds(low=(0,) * 7, high=(0,) * 7)


def test_vocab_layout_ranges_are_disjoint_and_cover_the_vocabulary():
    v = VocabLayout(text_size=300, image_codebook_size=256, action_bins=2048)
    t, i, a = v.range_of("text"), v.range_of("image"), v.range_of("action")
    assert t[1] == i[0] and i[1] == a[0] and a[1] == v.size
    assert v.token_id("<|mm2a|>") < t[0] and v.mask_id < t[0]
    with pytest.raises(KeyError):
        v.token_id("<|nope|>")
