"""Matching measured peaks with computed modes.

``pairing`` (measured-to-computed pairing by order, index or shape, MAC), ``assignment``
(the most probable assignment by frequency, spurious and unobserved peaks allowed),
``peak_prior`` (each peak's prior of being spurious, from its evidence) and
``checked_order`` (pairing by order, checked at the answer: the default without shapes).
"""
