#pragma once
// Queries over a mining index: prompts (or example images) -> ranked, filtered, de-duplicated, diverse hits,
// written as a mining run that `generate --manifest` consumes.
//
// Modes (each prompt reports which one ran):
//  - clip:    the prompt's CLIP text embedding against the crops' CLIP image embeddings (cosine).
//  - label:   no embeddings: the prompt names a category ("traffic cone" -> traffic_cone, datasets/categories.h)
//             and every crop annotated with it is a candidate, ranked by image quality. Only log crops carry
//             labels, so folder and URL images are never label hits.
//  - lexical: no embeddings either: the prompt is read through WordNet and the road words WordNet lacks
//             (lexicon.h: "lorry" -> truck, "pylon" -> traffic_cone, "motor vehicle" -> car, truck, ...), and every
//             crop annotated with a category it names is a candidate, ranked as in label mode. Each result keeps
//             the chain of relations that led there.
//  - example: an example image's classical descriptor (descriptor.h) against the crops' descriptors.
// `auto` picks clip when the index has CLIP vectors and a CLIP model is given, else lexical. A prompt that names
// no category gets no hits and says so, suggesting example mode with the user's own photos; when no prompt (and
// no example) can be served, that is an InputError.
//
// After ranking, in this order: thresholds (score, object size, truncation, occlusion, sharpness, visibility),
// near-duplicate removal (perceptual-hash Hamming distance against every hit already kept, so the best-ranked
// copy survives), diversity (at most `max_per_frame` hits from one source image/frame and `max_per_instance`
// from one tracked object), until `k` hits.
#include <filesystem>
#include <string>
#include <vector>

#include "mining/index.h"
#include "mining/lexicon.h"

namespace sd::mining {

enum class QueryMode { kAuto, kClip, kLabel, kLexical, kExample };
const char* ToString(QueryMode mode);
QueryMode QueryModeFromString(const std::string& s);  // InputError on an unknown mode

struct QueryOptions {
  std::vector<std::string> prompts;
  std::vector<std::filesystem::path> examples;  // example images (mode example / auto)
  QueryMode mode = QueryMode::kAuto;
  int k = 20;                      // hits per prompt
  // Thresholds; a figure an item does not have (-1, unknown) passes.
  double min_clip_score = 0.2;     // cosine, clip mode
  double min_example_score = 0.6;  // cosine, example mode
  double min_size_px = 32;         // shorter side of the object's 2D box in source pixels
  double max_truncation = 0.3;
  double max_occlusion = 0.5;
  double min_sharpness = 10;
  int min_visibility_level = -1;   // dataset level (nuScenes 1..4); -1 = no filter
  int max_hash_distance = 6;       // near duplicates: pHash Hamming distance <= this; < 0 disables
  int max_per_frame = 3;           // <= 0: unlimited
  int max_per_instance = 1;        // <= 0: unlimited
  const models::ClipEncoder* clip = nullptr;
  // Lexical mode's reader; null: category names and road words only (no WordNet).
  const Lexicon* lexicon = nullptr;
};

struct QueryHit {
  size_t row = 0;        // MiningIndex row
  double score = 0;      // clip / example: cosine; label: 1
  double quality = 0;    // 0..1, the label-mode ranking (ImageQuality)
  int rank = 0;          // 1-based within its prompt
};

struct PromptResult {
  std::string prompt;      // the text, or the example image's path
  QueryMode mode = QueryMode::kAuto;  // the mode that ran
  std::string category;    // label / lexical mode: the categories the prompt named, comma-separated
  std::vector<std::string> why;  // lexical mode: per category, the chain of relations; or why none was found
  size_t candidates = 0;   // ranked candidates examined
  size_t rejected_score = 0, rejected_quality = 0, rejected_duplicate = 0, rejected_diversity = 0;
  std::vector<QueryHit> hits;
};

// The category a prompt names, by canonical or dataset name ("traffic cone", "trafficcone", "Pedestrian")
// or by all of a category's name words appearing in it ("orange traffic cone"); empty when none.
std::string CategoryForPrompt(const std::string& prompt);

// 0..1: larger, sharper, less truncated and less occluded crops first.
double ImageQuality(const MinedItem& item);
double ImageQuality(const ItemSummary& item);

std::vector<PromptResult> RunQuery(const MiningIndex& index, const QueryOptions& options);

// The mining run folder, written atomically (StagingDirectory; an existing folder is refused unless
// `overwrite`): manifest.jsonl (one MinedItem JSON per hit plus prompt, mode, score, quality, rank; crop and
// mask paths relative to the run), crops/ and masks/ (copies, so the run outlives the index), run.json
// (the query, the counts of rejected candidates per prompt) and index.html (a contact sheet).
void WriteMiningRun(const std::filesystem::path& run_dir, const MiningIndex& index,
                    const std::vector<PromptResult>& results, const QueryOptions& options, bool overwrite);

// One hit of a mining run, as `generate --manifest` reads it back.
struct ManifestEntry {
  MinedItem item;                     // crop_file / mask_file resolved to absolute paths
  std::string prompt, mode;
  double score = 0, quality = 0;
  int rank = 0;
};
// InputError naming the file and line for a malformed line or a crop file that is missing.
std::vector<ManifestEntry> ReadManifest(const std::filesystem::path& manifest_jsonl);

}  // namespace sd::mining
