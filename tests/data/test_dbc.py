"""DBC loading (lenient with warnings, strict refusals) and the vectorised signal decoder,
checked bit for bit against cantools on random payloads."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from cantools.database.can import Message
from cantools.database.can import Signal as CanSignal

from helpers.paths import CANEDGE, KONA
from parknss.data.canwrite import encode_message
from parknss.data.dbc import (
    DbcWarning,
    bytes_needed,
    clear_dbc_cache,
    decode_signal,
    load_dbc,
)
from parknss.errors import DataError

KONA_DBC = KONA / "pcan.dbc"
CANMOD_DBC = CANEDGE / "canmod-gps.dbc"

# Big- and little-endian, signed, IEEE float, value tables, multiplexing (with a
# multiplexed multiplexer), an extended id and a signal crossing 9 bytes' worth of bits.
MIXED_DBC = """VERSION ""

NS_ :
	CM_
	VAL_

BS_:

BU_: ECU

BO_ 256 MIXED: 8 ECU
 SG_ BigSigned : 7|12@0- (0.5,-3) [-1000|1000] "deg" Vector__XXX
 SG_ LittleUnsigned : 16|20@1+ (0.01,0) [0|10000] "km/h" Vector__XXX
 SG_ Flag : 36|1@1+ (1,0) [0|1] "" Vector__XXX
 SG_ BigOdd : 45|11@0+ (1,0) [0|2047] "" Vector__XXX
 SG_ Gear : 56|3@1+ (1,0) [0|7] "" Vector__XXX
 SG_ Tail : 59|5@1- (2,1) [-31|31] "" Vector__XXX

BO_ 257 FLOATS: 8 ECU
 SG_ F32 : 0|32@1- (1,0) [-1e38|1e38] "" Vector__XXX
 SG_ F32BE : 39|32@0- (2,1) [-1e38|1e38] "" Vector__XXX

BO_ 258 DOUBLE: 8 ECU
 SG_ D64 : 0|64@1- (1,0) [-1e308|1e308] "" Vector__XXX

BO_ 2147484160 EXT64: 8 ECU
 SG_ U64 : 0|64@1+ (1,0) [0|1.8e19] "" Vector__XXX

BO_ 259 MUXED: 8 ECU
 SG_ Mux M : 0|4@1+ (1,0) [0|15] "" ECU
 SG_ A m0 : 8|16@1- (0.1,0) [-3276.8|3276.7] "m/s^2" ECU
 SG_ B m1 : 15|16@0+ (1,0) [0|65535] "" ECU
 SG_ C m1 : 31|8@0- (1,-10) [-138|117] "" ECU
 SG_ Sub m2M : 44|4@1+ (1,0) [0|15] "" ECU
 SG_ Deep m3 : 48|8@1+ (1,0) [0|255] "" ECU
 SG_ Mode m0 : 40|3@1+ (1,0) [0|7] "" ECU

BO_ 260 SHORT: 3 ECU
 SG_ Three : 0|24@1+ (1,0) [0|16777215] "" ECU

VAL_ 256 Gear 0 "P" 1 "R" 2 "N" 3 "D" ;
VAL_ 259 Mode 1 "ECO" 2 "SPORT" ;
SIG_VALTYPE_ 257 F32 : 1;
SIG_VALTYPE_ 257 F32BE : 1;
SIG_VALTYPE_ 258 D64 : 2;
SG_MUL_VAL_ 259 Deep Sub 3-3;
SG_MUL_VAL_ 259 Sub Mux 2-2;
SG_MUL_VAL_ 259 A Mux 0-0;
SG_MUL_VAL_ 259 Mode Mux 0-0;
SG_MUL_VAL_ 259 B Mux 1-1;
SG_MUL_VAL_ 259 C Mux 1-1;
"""

OVERLAP_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 400 TOYOTA_LIKE: 8 ECU
 SG_ STEER_ANGLE : 3|12@0- (1.5,0) [-1500|1500] "deg" ECU
 SG_ STEER_FRACTION : 39|4@0- (0.1,0) [-0.7|0.7] "deg" ECU
 SG_ STEER_RATE : 36|12@0- (1,0) [-2000|2000] "deg/s" ECU
 SG_ WHOLE : 7|16@0+ (1,0) [0|65535] "" ECU
"""


@pytest.fixture
def mixed(tmp_path) -> Path:
    p = tmp_path / "mixed.dbc"
    p.write_text(MIXED_DBC)
    return p


def _alone(signal) -> CanSignal:
    """The signal without its multiplexer: cantools decodes it unconditionally."""
    return CanSignal(
        signal.name,
        signal.start,
        signal.length,
        byte_order=signal.byte_order,
        is_signed=signal.is_signed,
        conversion=signal.conversion,
    )


def _reference(message, signal, data: np.ndarray) -> np.ndarray:
    """cantools' own decode of the signal in each frame (a one-signal message)."""
    single = Message(message.frame_id, message.name, message.length, [_alone(signal)], strict=False)
    out = []
    for row in data:
        v = single.decode(row.tobytes(), decode_choices=True, allow_truncated=True)[signal.name]
        out.append(str(getattr(v, "name", v)) if signal.choices else float(v))
    return np.array(out, dtype=object if signal.choices else np.float64)


def _check_db(db, n: int, seed: int) -> int:
    rng = np.random.default_rng(seed)
    checked = 0
    for message in db.messages:
        data = rng.integers(0, 256, (n, message.length), dtype=np.uint8)
        for signal in message.signals:
            got = decode_signal(message, _alone(signal), data)
            ref = _reference(message, signal, data)
            assert got.mask.all()
            if signal.choices:
                assert got.values.dtype == object
                assert list(got.values) == list(ref), (message.name, signal.name)
            else:
                np.testing.assert_array_equal(
                    got.values, ref, err_msg=f"{message.name}.{signal.name}"
                )
            checked += 1
    return checked


def test_decoder_equals_cantools_on_every_signal_of_a_mixed_dbc(mixed):
    db = load_dbc(mixed, strict=True).db
    assert _check_db(db, 3000, seed=1) == 18


@pytest.mark.realdata
@pytest.mark.filterwarnings("ignore::parknss.data.dbc.DbcWarning")
@pytest.mark.parametrize("path", [KONA_DBC, CANMOD_DBC], ids=["kona", "canmod"])
def test_decoder_equals_cantools_on_every_signal_of_the_shared_dbcs(path):
    db = load_dbc(path).db
    assert _check_db(db, 2000, seed=2) == sum(len(m.signals) for m in db.messages)


def test_multiplexed_signals_only_where_their_multiplexer_selects_them(mixed):
    db = load_dbc(mixed).db
    msg = db.get_message_by_name("MUXED")
    rng = np.random.default_rng(3)
    data = rng.integers(0, 256, (4000, 8), dtype=np.uint8)
    data[:, 0] = (data[:, 0] & 0xF0) | rng.integers(0, 5, 4000)  # mux 0..4 (4: no branch)
    data[:, 5] = (data[:, 5] & 0x0F) | (rng.integers(2, 5, 4000) << 4).astype(np.uint8)  # Sub
    decoded = {s.name: decode_signal(msg, s, data) for s in msg.signals}
    for k, row in enumerate(data):
        try:
            ref = msg.decode(row.tobytes())
        except Exception:  # cantools refuses a frame with an unknown multiplexer value
            ref = {"Mux": int(row[0] & 0xF)}
            if ref["Mux"] == 2:
                ref["Sub"] = int(row[5] >> 4)
        for name, d in decoded.items():
            assert d.mask[k] == (name in ref), (k, name)
            if name in ref:
                want = ref[name]
                want = (
                    str(getattr(want, "name", want))
                    if msg.get_signal_by_name(name).choices
                    else float(want)
                )
                assert d.values[k] == want, (k, name)
    assert decoded["Deep"].mask.sum() == ((data[:, 0] & 0xF == 2) & (data[:, 5] >> 4 == 3)).sum()
    assert decoded["A"].n_other_mux == (data[:, 0] & 0xF != 0).sum()
    assert set(decoded["Mode"].values[decoded["Mode"].mask]) <= {
        "0",
        "ECO",
        "SPORT",
        "3",
        "4",
        "5",
        "6",
        "7",
    }


def test_frames_too_short_are_masked_and_counted(mixed):
    db = load_dbc(mixed).db
    msg = db.get_message_by_name("MIXED")
    rng = np.random.default_rng(4)
    data = rng.integers(0, 256, (500, 8), dtype=np.uint8)
    lengths = rng.integers(0, 9, 500)
    data[np.arange(8)[None, :] >= lengths[:, None]] = 0
    for signal in msg.signals:
        d = decode_signal(msg, signal, data, lengths)
        need = bytes_needed(signal)
        np.testing.assert_array_equal(d.mask, lengths >= need)
        assert d.n_short == int((lengths < need).sum())
        for k in np.flatnonzero(lengths >= need)[:50]:  # cantools agrees where it decodes
            ref = msg.decode(data[k, : lengths[k]].tobytes(), allow_truncated=True)
            v = ref[signal.name]
            assert d.values[k] == (str(getattr(v, "name", v)) if signal.choices else float(v))
    short = decode_signal(
        db.get_message_by_name("SHORT"),
        db.get_message_by_name("SHORT").signals[0],
        np.zeros((3, 2), np.uint8),
    )
    assert not short.mask.any() and short.n_short == 3  # payloads narrower than the signal


def test_encode_is_the_inverse_of_decode_up_to_quantisation(mixed):
    db = load_dbc(mixed).db
    rng = np.random.default_rng(5)
    msg = db.get_message_by_name("MIXED")
    n = 1000
    values = {
        "BigSigned": rng.uniform(-1000, 1000, n),
        "LittleUnsigned": rng.uniform(0, 10000, n),
        "Flag": rng.integers(0, 2, n).astype(float),
        "BigOdd": rng.integers(0, 2048, n).astype(float),
        "Gear": rng.choice(np.array(["P", "R", "N", "D"], dtype=object), n),
        "Tail": rng.integers(-15, 16, n) * 2.0 + 1,
    }
    data = encode_message(msg, values)
    for k in range(0, n, 97):  # the same bytes as cantools' encoder
        one = {s: (v[k] if isinstance(v[k], str) else float(v[k])) for s, v in values.items()}
        assert data[k].tobytes() == msg.encode(one, strict=False)
    for signal in msg.signals:
        got = decode_signal(msg, signal, data).values
        want = values[signal.name]
        if signal.choices:
            assert list(got) == list(want)
        else:
            np.testing.assert_allclose(got, want, atol=signal.scale / 2 + 1e-9, rtol=0)
    floats = db.get_message_by_name("FLOATS")
    x = rng.normal(0, 1e3, n)
    data = encode_message(floats, {"F32": x, "F32BE": x})
    np.testing.assert_array_equal(
        decode_signal(floats, floats.signals[0], data).values, x.astype(np.float32)
    )
    mux = db.get_message_by_name("MUXED")
    page = np.array([0.0, 1.0] * 50)
    data = encode_message(mux, {"Mux": page, "A": np.full(100, -12.3), "B": np.full(100, 777.0)})
    a, b = (decode_signal(mux, mux.get_signal_by_name(s), data) for s in ("A", "B"))
    np.testing.assert_array_equal(a.mask, page == 0)
    np.testing.assert_allclose(a.values[a.mask], -12.3)
    np.testing.assert_array_equal(b.values[b.mask], 777.0)


# ------------------------------------------------------------------------------ loading


@pytest.mark.realdata
def test_kona_dbc_loads_leniently_with_one_warning_and_strict_refuses_it():
    clear_dbc_cache()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loaded = load_dbc(KONA_DBC)
    assert loaded.warnings == ("no BS_:/BU_: sections (empty ones assumed)",)
    lines = [str(w.message) for w in caught if issubclass(w.category, DbcWarning)]
    assert lines == [f"DBC file {KONA_DBC}: no BS_:/BU_: sections (empty ones assumed)"]
    assert len(loaded.db.messages) == 107
    steering = loaded.message("Steering")
    assert steering.frame_id == 0x2B0 and steering.get_signal_by_name("Angle").unit == "Deg"
    with warnings.catch_warnings(record=True) as again:  # cached: no second warning
        warnings.simplefilter("always")
        assert load_dbc(KONA_DBC) is loaded
    assert not again
    with pytest.raises(DataError) as exc:
        load_dbc(KONA_DBC, strict=True)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"DBC file {KONA_DBC}: refused in strict mode")
    assert "can.strict_dbc: false" in msg


@pytest.mark.realdata
def test_canmod_dbc_loads_strictly_without_warnings():
    clear_dbc_cache()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_dbc(CANMOD_DBC).warnings == ()
        assert load_dbc(CANMOD_DBC, strict=True).warnings == ()


def test_overlapping_signals_are_a_warning_leniently_and_an_error_strictly(tmp_path):
    p = tmp_path / "toyota_like.dbc"
    p.write_text(OVERLAP_DBC)
    clear_dbc_cache()
    with pytest.warns(DbcWarning, match="message 'TOYOTA_LIKE': signals '.*' and '.*' overlap"):
        loaded = load_dbc(p)
    pairs = {frozenset(re.findall(r"'(\w+)' and '(\w+)'", w)[0]) for w in loaded.warnings}
    assert pairs == {
        frozenset(("STEER_ANGLE", "WHOLE")),
        frozenset(("STEER_FRACTION", "STEER_RATE")),
    }
    msg = loaded.message("TOYOTA_LIKE")
    data = np.random.default_rng(6).integers(0, 256, (500, 8), dtype=np.uint8)
    for signal in msg.signals:  # each overlapping signal still decodes by its own bits
        np.testing.assert_array_equal(
            decode_signal(msg, signal, data).values, _reference(msg, signal, data)
        )
    with pytest.raises(DataError, match=r"toyota_like\.dbc: refused in strict mode \(") as exc:
        load_dbc(p, strict=True)
    assert "\n" not in str(exc.value) and "are overlapping in message TOYOTA_LIKE" in str(exc.value)


def test_dbc_without_any_section_header_and_bad_files(tmp_path):
    p = tmp_path / "bare.dbc"
    p.write_text('VERSION ""\n\nBO_ 16 ONLY: 2 XXX\n SG_ X : 0|16@1+ (1,0) [0|1] "" XXX\n')
    clear_dbc_cache()
    with pytest.warns(DbcWarning, match="no BS_:/BU_: sections"):
        assert load_dbc(p).message("ONLY").frame_id == 16
    with pytest.raises(DataError, match=r"bare\.dbc: refused in strict mode \(no BS_:/BU_: sec"):
        load_dbc(p, strict=True)  # cantools parses it; strict refuses what lenient tolerates
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ this is not a DBC\n")
    for strict in (False, True):
        with pytest.raises(DataError) as exc:
            load_dbc(bad, strict=strict)
        assert "\n" not in str(exc.value) and f"DBC file {bad}:" in str(exc.value)
    with pytest.raises(DataError, match=r"DBC file .*missing\.dbc not found"):
        load_dbc(tmp_path / "missing.dbc")
