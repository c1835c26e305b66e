#!/usr/bin/python3
"""Builds a tiny CLIP model whose embedding space is colour, so the mining tests can check CLIP-mode retrieval
end to end with a known right answer: "red ..." must rank red crops first.

  image: the crop's chromaticity (per-channel mean minus the grey mean) -> (r, g, b, 0.01)
  text:  the first token after <start>; the byte tokens of 'r', 'g' and 'b' map to the r, g, b axes, every
         token also carries a small fourth component (so unknown words embed to a valid, colourless vector).
The contracts are the real "clip_image" / "clip_text" ones (src/models/clip.h); the vocabulary is the handmade
merges file of the CLIP stage tests.
Usage: make_mining_test_models.py OUT_DIR
"""
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from make_stage_test_models import MERGES, VOCAB  # noqa: E402  (the handmade merges: test data)
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

SOURCE = "tools/testing/make_mining_test_models.py"
LICENSE = "Apache-2.0"


def byte_token(ch: str) -> int:
    """Id of a printable ASCII byte in CLIP's byte order (bytes_to_unicode puts '!'..'~' first)."""
    return ord(ch) - ord("!")


class ColourImage(torch.nn.Module):
    def forward(self, image):
        mean = image.mean(dim=(2, 3))
        chroma = mean - mean.mean(dim=1, keepdim=True)
        return torch.cat([chroma, torch.full_like(chroma[:, :1], 0.01)], dim=1)


class ColourText(torch.nn.Module):
    def __init__(self):
        super().__init__()
        table = torch.zeros(VOCAB, 4)
        table[:, 3] = 0.05
        for axis, ch in enumerate("rgb"):
            table[byte_token(ch), axis] = 1.0
        self.register_buffer("table", table)

    def forward(self, tokens):
        ids = tokens.to(torch.int64)
        return self.table[ids[:, 1]]


def main():
    out = os.path.join(sys.argv[1], "clip_colour")
    os.makedirs(out, exist_ok=True)
    size, ctx = 32, 77
    embedding = tensor_spec("embedding", [-1, 4], (-1e4, 1e4), "NC")
    save_scripted(ColourImage().eval(), os.path.join(out, "clip_image.pt"),
                  contract("clip_image", "clip-colour-image",
                           [tensor_spec("image", [-1, 3, size, size], (0, 1), "NCHW", "srgb")], [embedding],
                           {"embed_dim": 4, "image_size": size}, SOURCE, LICENSE))
    save_scripted(ColourText().eval(), os.path.join(out, "clip_text.pt"),
                  contract("clip_text", "clip-colour-text",
                           [tensor_spec("tokens", [-1, ctx], (0, VOCAB - 1), "NL", "token_ids")], [dict(embedding)],
                           {"embed_dim": 4, "context_length": ctx, "vocab_size": VOCAB}, SOURCE, LICENSE))
    with open(os.path.join(out, "bpe_simple_vocab_16e6.txt"), "w") as f:
        f.write(MERGES)


if __name__ == "__main__":
    main()
