"""Gymnasium environments of wip-gym."""
