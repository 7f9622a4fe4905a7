"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS; identifier node and offline fits."""
