"""``parknss identify``: the whole path from a car's logs to its plant and model card as
one resumable pipeline (:mod:`.pipeline`), its stage book (:mod:`.stages`), what it may
reuse and the checks that say so (:mod:`.reuse`), the data facts (:mod:`.data_stage`)
and the model card (:mod:`.card`, :mod:`.card_html`)."""
