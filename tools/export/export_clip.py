#!/usr/bin/env python3
"""Exports a CLIP model to the SynthDrive "clip_image" / "clip_text" contracts (src/models/clip.h).

NOT RUN IN THIS REPOSITORY'S CI: it needs the real weights (downloaded by open_clip or OpenAI's clip package
from their hosts) and those packages, neither of which the build machine has. It was written against the
published APIs of open_clip (>= 2.20: create_model_and_transforms, tokenizer.default_bpe, encode_image,
encode_text) and OpenAI's clip package (clip.load(..., jit=False)); the contracts it writes are what the C++
side checks, and its self-check below compares the exported modules against the eager model.

Writes, into OUT_DIR:
  clip_image.pt               image [N, 3, S, S] sRGB 0..1 -> embedding [N, D]; the model's mean / std
                              normalisation is baked in, so C++ only resizes and crops
  clip_text.pt                tokens [N, 77] float32 (exact integers) -> embedding [N, D]; the module casts
                              to int64 itself because the SynthDrive runtime moves float32 tensors only
  bpe_simple_vocab_16e6.txt   the BPE merges, uncompressed (the C++ tokenizer reads plain text)

Usage:
  export_clip.py OUT_DIR [--arch ViT-B-32] [--pretrained openai] [--backend open_clip|openai|transformers]
  e.g. --arch ViT-L-14 --pretrained openai   (OpenAI's ViT-L/14, D = 768, S = 224)
  --backend transformers --pretrained HF_FOLDER --vocab bpe_simple_vocab_16e6.txt.gz
      a Hugging Face CLIPModel checkpoint folder (e.g. a download of openai/clip-vit-base-patch32); its BPE
      merges are OpenAI's, given by --vocab. --pretrained random builds the architecture of the default
      CLIPConfig (ViT-B/32) with random weights (--seed): no checkpoint, for proving the runtime on the real
      architecture (tools/gpu/clip_check.py).
Licences: OpenAI CLIP weights MIT; open_clip code MIT; LAION-trained open_clip weights MIT.
"""
import argparse
import gzip
import json
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

EXPORTER = "tools/export/export_clip.py"
OPENAI_MEAN = (0.48145466, 0.4578275, 0.40821073)
OPENAI_STD = (0.26862954, 0.26130258, 0.27577711)


class ImageEncoder(torch.nn.Module):
    def __init__(self, model, mean, std):
        super().__init__()
        self.visual = model.visual
        self.register_buffer("mean", torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1))

    def forward(self, image):
        # CLIP's visual tower returns the projected embedding (encode_image == visual(x) in both packages).
        return self.visual((image - self.mean) / self.std).float()


class TextEncoder(torch.nn.Module):
    """encode_text, with the float32 -> int64 cast the runtime boundary needs in front."""

    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, tokens):
        return self.model.encode_text(tokens.to(torch.int64)).float()


def _run_layers(layers, x, mask):
    """transformers' encoder layers over x with an additive attention mask (None: none)."""
    for layer in layers:
        try:  # transformers 4.x takes the causal mask apart; 5.x one mask
            out = layer(x, attention_mask=mask, causal_attention_mask=None)
        except TypeError:
            out = layer(x, attention_mask=mask)
        x = out[0] if isinstance(out, (tuple, list)) else out
    return x


class HFClip(torch.nn.Module):
    """A transformers CLIPModel behind the open_clip / OpenAI interface the encoders above use."""

    class Visual(torch.nn.Module):
        def __init__(self, model):
            super().__init__()
            self.vision_model, self.projection = model.vision_model, model.visual_projection

        def forward(self, pixels):
            # The vision tower step by step: transformers casts the pixels to the patch weights' dtype, which a
            # trace records as a constant (float32), so the module converted to half (RuntimeOptions::half)
            # fed float32 into half weights. Here every dtype follows the input's.
            vm = self.vision_model
            emb = vm.embeddings
            x = emb.patch_embedding(pixels).flatten(2).transpose(1, 2)
            cls = emb.class_embedding.view(1, 1, -1).expand(x.shape[0], 1, -1)
            # Position rows read from the table itself: the position_ids buffer is int64, and LibTorch's
            # Module::to(kHalf) converts it too.
            x = torch.cat([cls, x], dim=1) + emb.position_embedding.weight[: x.shape[1] + 1][None]
            x = vm.pre_layrnorm(x)
            x = _run_layers(vm.encoder.layers, x, None)
            return self.projection(vm.post_layernorm(x[:, 0, :]))

    def __init__(self, model):
        super().__init__()
        self.model = model
        self.visual = HFClip.Visual(model)
        self.context_length = int(model.config.text_config.max_position_embeddings)
        self.vocab_size = int(model.config.text_config.vocab_size)

    def encode_image(self, pixels):
        return self.visual(pixels)

    def encode_text(self, ids):
        # The text tower, layer by layer, with the causal mask made from the input: transformers builds its own
        # mask with the device of the tracing run as a constant, so a module traced on the CPU failed on CUDA
        # ("attn_bias is on cpu"). A mask derived from `ids` follows the input's device in the trace.
        tm = self.model.text_model
        te = tm.embeddings  # the token and position tables, without the int64 position_ids buffer (see Visual)
        x = te.token_embedding(ids) + te.position_embedding.weight[: ids.shape[1]][None]
        ones = torch.ones_like(x[0, :, 0])
        blocked = torch.triu(ones[:, None] * ones[None, :], diagonal=1)
        # -65504, half's lowest: a trace keeps the constant, and float32's lowest would be -inf in half (0 * -inf
        # is NaN); exp(-65504) is 0 in both.
        mask = (blocked * -65504.0)[None, None].expand(ids.shape[0], 1, -1, -1)
        x = tm.final_layer_norm(_run_layers(tm.encoder.layers, x, mask))
        # Pooled at the end-of-text token, the largest id in OpenAI's vocabulary (clip.model.encode_text's rule);
        # the padding after it is zeros, which the causal mask keeps from reaching the tokens before it.
        pooled = x[torch.arange(x.shape[0], device=x.device), ids.argmax(dim=-1)]
        return self.model.text_projection(pooled)


def openai_tokenize(bpe_path, context):
    """OpenAI's clip.tokenize (sot, BPE ids, eot, zeros; truncated with eot last), from the BPE merges alone:
    the vocabulary is the 256 byte symbols, the same with '</w>', every merge, then the two specials."""
    from transformers import CLIPTokenizer
    import tempfile
    opener = gzip.open if bpe_path.endswith(".gz") else open
    with opener(bpe_path, "rt", encoding="utf-8") as f:
        merges = f.read().split("\n")[1:49152 - 256 - 2 + 1]
    byte_symbols = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + \
        list(range(ord("®"), ord("ÿ") + 1))
    extra = [b for b in range(256) if b not in byte_symbols]
    symbols = [chr(b) for b in byte_symbols] + [chr(256 + i) for i in range(len(extra))]
    vocab = symbols + [v + "</w>" for v in symbols] + ["".join(m.split()) for m in merges]
    vocab += ["<|startoftext|>", "<|endoftext|>"]
    folder = tempfile.mkdtemp(prefix="clip_vocab_")
    with open(os.path.join(folder, "vocab.json"), "w", encoding="utf-8") as f:
        json.dump({v: i for i, v in enumerate(vocab)}, f)
    with open(os.path.join(folder, "merges.txt"), "w", encoding="utf-8") as f:
        f.write("#version: 0.2\n" + "\n".join(merges) + "\n")
    hf = CLIPTokenizer(os.path.join(folder, "vocab.json"), os.path.join(folder, "merges.txt"))
    sot, eot = vocab.index("<|startoftext|>"), vocab.index("<|endoftext|>")

    def tokenize(texts):
        out = torch.zeros(len(texts), context, dtype=torch.int64)
        for row, text in enumerate(texts):
            ids = [sot] + hf(text, add_special_tokens=False)["input_ids"] + [eot]
            ids = ids[:context]
            ids[-1] = eot
            out[row, :len(ids)] = torch.tensor(ids)
        return out
    return tokenize


def load(backend, arch, pretrained, vocab=None, seed=0):
    if backend == "transformers":
        import transformers
        if not vocab:
            sys.exit("export_clip: --backend transformers needs --vocab (OpenAI's bpe_simple_vocab_16e6.txt.gz)")
        if pretrained == "random":
            torch.manual_seed(seed)
            hf = transformers.CLIPModel(transformers.CLIPConfig())
            source = f"transformers {transformers.__version__} CLIPModel(CLIPConfig()) random init, seed {seed}"
        else:
            hf = transformers.CLIPModel.from_pretrained(pretrained)
            source = f"transformers {transformers.__version__} CLIPModel {pretrained}"
        model = HFClip(hf.float().eval())
        size = int(hf.config.vision_config.image_size)
        tokenize = openai_tokenize(vocab, model.context_length)
        return model.eval(), OPENAI_MEAN, OPENAI_STD, size, vocab, tokenize, source, None
    if backend == "open_clip":
        import open_clip
        model, _, preprocess = open_clip.create_model_and_transforms(arch, pretrained=pretrained, device="cpu")
        cfg = getattr(model.visual, "preprocess_cfg", {}) or {}
        mean = tuple(cfg.get("mean", getattr(model.visual, "image_mean", None) or OPENAI_MEAN))
        std = tuple(cfg.get("std", getattr(model.visual, "image_std", None) or OPENAI_STD))
        size = model.visual.image_size
        size = size[0] if isinstance(size, (tuple, list)) else int(size)
        bpe = open_clip.tokenizer.default_bpe()
        tokenize = open_clip.get_tokenizer(arch)
        source = f"open_clip {open_clip.__version__} {arch} pretrained={pretrained}"
    else:
        import clip
        model, preprocess = clip.load(arch.replace("-", "/", 1) if "/" not in arch else arch, device="cpu", jit=False)
        mean, std = OPENAI_MEAN, OPENAI_STD
        size = int(model.visual.input_resolution)
        bpe = os.path.join(os.path.dirname(clip.__file__), "bpe_simple_vocab_16e6.txt.gz")
        tokenize = clip.tokenize
        source = f"openai/CLIP {arch}"
    model = model.float().eval()
    return model, mean, std, size, bpe, tokenize, source, preprocess


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--arch", default="ViT-B-32")
    ap.add_argument("--pretrained", default="openai")
    ap.add_argument("--backend", choices=["open_clip", "openai", "transformers"], default="open_clip")
    ap.add_argument("--vocab", help="BPE merges file (transformers backend)")
    ap.add_argument("--seed", type=int, default=0, help="random initialisation seed (--pretrained random)")
    args = ap.parse_args()
    os.makedirs(args.out_dir, exist_ok=True)

    model, mean, std, size, bpe, tokenize, source, preprocess = load(args.backend, args.arch, args.pretrained,
                                                                      args.vocab, args.seed)
    context = int(model.context_length)
    vocab = int(model.vocab_size)
    with torch.no_grad():
        dim = int(model.encode_text(tokenize(["a car"])).shape[1])
    assert vocab < 2 ** 24, "token ids must be exact in float32"

    image_enc, text_enc = ImageEncoder(model, mean, std).eval(), TextEncoder(model).eval()
    # Tracing, not scripting: both towers are static graphs for a fixed input size, and the ViT code of both
    # packages uses Python features TorchScript's compiler does not accept.
    with torch.no_grad():
        traced_image = torch.jit.trace(image_enc, torch.rand(2, 3, size, size), check_trace=True)
        traced_text = torch.jit.trace(text_enc, tokenize(["a photo of a car", "a bus"]).float(), check_trace=True)

    # Self-check against the eager model: the exported image path from 0..1 pixels must equal
    # encode_image(normalise(x)), and the text path encode_text(ids).
    with torch.no_grad():
        x = torch.rand(3, 3, size, size)
        ref_i = model.encode_image((x - torch.tensor(mean).view(1, 3, 1, 1)) / torch.tensor(std).view(1, 3, 1, 1))
        ids = tokenize(["a red car parked on the street", "a pedestrian", "traffic cone"])
        ref_t = model.encode_text(ids)
        err_i = float((traced_image(x) - ref_i).abs().max())
        err_t = float((traced_text(ids.float()) - ref_t).abs().max())
    if err_i > 1e-4 or err_t > 1e-4:
        sys.exit(f"export_clip: exported modules differ from the eager model (image {err_i:g}, text {err_t:g})")

    embedding = tensor_spec("embedding", [-1, dim], (-1e4, 1e4), "NC")
    image_contract = contract("clip_image", f"clip-{args.arch.lower()}-{args.pretrained}-image",
                              [tensor_spec("image", [-1, 3, size, size], (0, 1), "NCHW", "srgb")], [embedding],
                              {"embed_dim": dim, "image_size": size}, source, "MIT", exporter=EXPORTER,
                              verification={"max_abs_diff_vs_eager": err_i})
    text_contract = contract("clip_text", f"clip-{args.arch.lower()}-{args.pretrained}-text",
                             [tensor_spec("tokens", [-1, context], (0, vocab - 1), "NL", "token_ids")],
                             [dict(embedding)], {"embed_dim": dim, "context_length": context, "vocab_size": vocab},
                             source, "MIT", exporter=EXPORTER, verification={"max_abs_diff_vs_eager": err_t})
    save_scripted(traced_image, os.path.join(args.out_dir, "clip_image.pt"), image_contract)
    save_scripted(traced_text, os.path.join(args.out_dir, "clip_text.pt"), text_contract)
    opener = gzip.open if bpe.endswith(".gz") else open
    with opener(bpe, "rt", encoding="utf-8") as src, \
            open(os.path.join(args.out_dir, "bpe_simple_vocab_16e6.txt"), "w", encoding="utf-8") as dst:
        dst.write(src.read())
    # Token ids the C++ tokenizer must reproduce (src/models/clip_tokenizer.h), for a manual cross-check.
    probe = ["a photo of a red car", "Ein Fahrrad, 2 Räder!", "it's a traffic-cone"]
    with open(os.path.join(args.out_dir, "tokenizer_probe.json"), "w") as f:
        json.dump({t: [int(i) for i in tokenize([t])[0].tolist()] for t in probe}, f, ensure_ascii=False)
    print(f"export_clip: {source}: D={dim}, S={size}, context {context}, vocab {vocab}; "
          f"max |diff| vs eager: image {err_i:.2e}, text {err_t:.2e} -> {args.out_dir}")


if __name__ == "__main__":
    main()
