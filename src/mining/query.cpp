#include "mining/query.h"

#include <algorithm>
#include <cctype>
#include <functional>
#include <map>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/html.h"
#include "io/json.h"
#include "mining/descriptor.h"
#include "models/clip.h"

namespace sd::mining {

namespace fs = std::filesystem;
using nlohmann::json;

const char* ToString(QueryMode mode) {
  switch (mode) {
    case QueryMode::kAuto: return "auto";
    case QueryMode::kClip: return "clip";
    case QueryMode::kLabel: return "label";
    case QueryMode::kLexical: return "lexical";
    case QueryMode::kExample: return "example";
  }
  return "?";
}

QueryMode QueryModeFromString(const std::string& s) {
  for (QueryMode m : {QueryMode::kAuto, QueryMode::kClip, QueryMode::kLabel, QueryMode::kLexical, QueryMode::kExample})
    if (s == ToString(m)) return m;
  throw InputError({}, Msg() << "unknown query mode '" << s << "' (expected auto, clip, label, lexical or example)");
}

namespace {

std::vector<std::string> Words(const std::string& text) {
  std::vector<std::string> words;
  std::string w;
  for (char c : text + " ") {
    if (std::isalnum(static_cast<unsigned char>(c))) {
      w += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    } else if (!w.empty()) {
      words.push_back(w);
      w.clear();
    }
  }
  return words;
}

std::string Join(const std::vector<std::string>& words, const std::string& sep) {
  std::string s;
  for (size_t i = 0; i < words.size(); ++i) s += (i ? sep : "") + words[i];
  return s;
}

}  // namespace

std::string CategoryForPrompt(const std::string& prompt) {
  const std::vector<std::string> words = Words(prompt);
  if (words.empty()) return {};
  for (const std::string& form : {prompt, Join(words, "_"), Join(words, "")})
    if (auto c = FindCategory(form)) return c->name;
  // Every word of a category's canonical name in the prompt: the category with the most words wins, so
  // "construction vehicle" is not claimed by a one-word category that happens to share a word.
  const std::set<std::string> have(words.begin(), words.end());
  std::string best;
  size_t best_words = 0;
  for (const CategoryInfo& c : Categories()) {
    const std::vector<std::string> need = Words(c.name);
    const bool all = std::all_of(need.begin(), need.end(), [&](const std::string& w) { return have.count(w) > 0; });
    if (all && need.size() > best_words) best = c.name, best_words = need.size();
  }
  return best;
}

double ImageQuality(const ItemSummary& item) {
  const double size = std::clamp(item.object_size_px / 128.0, 0.0, 1.0);
  const double sharp = item.sharpness < 0 ? 0.5 : std::clamp(item.sharpness / 200.0, 0.0, 1.0);
  const double trunc = item.truncation < 0 ? 0.0 : std::clamp<double>(item.truncation, 0.0, 1.0);
  const double occl = item.occlusion < 0 ? 0.0 : std::clamp<double>(item.occlusion, 0.0, 1.0);
  // Size and sharpness matter through a square root: a 64-pixel cone is usable, a fully occluded one is not.
  return std::sqrt(size) * std::sqrt(sharp) * (1 - trunc) * (1 - occl);
}

double ImageQuality(const MinedItem& item) {
  // Through the table's float figures, so that ranking from the table and from a record agree exactly.
  return ImageQuality(ItemSummary{item.category, static_cast<float>(ObjectSizePx(item)), static_cast<float>(item.truncation),
                                  static_cast<float>(item.occlusion), static_cast<float>(item.sharpness)});
}

namespace {

struct Candidate {
  size_t row;
  double score;
};

// The hit list of one prompt from its ranked candidates: thresholds, near-duplicates, diversity.
void Select(const MiningIndex& index, const std::vector<Candidate>& ranked, double min_score,
            const QueryOptions& o, PromptResult& result) {
  result.hits.clear();
  result.candidates = ranked.size();
  result.rejected_score = result.rejected_quality = result.rejected_duplicate = result.rejected_diversity = 0;
  std::vector<uint64_t> kept_hashes;
  std::map<std::string, int> per_frame, per_instance;
  for (const Candidate& c : ranked) {
    if (static_cast<int>(result.hits.size()) >= o.k) break;
    const MinedItem& item = index.item(c.row);
    if (c.score < min_score) {
      ++result.rejected_score;
      continue;
    }
    const bool bad_quality = ObjectSizePx(item) < o.min_size_px ||
                             (item.truncation >= 0 && item.truncation > o.max_truncation) ||
                             (item.occlusion >= 0 && item.occlusion > o.max_occlusion) ||
                             (item.sharpness >= 0 && item.sharpness < o.min_sharpness) ||
                             (o.min_visibility_level >= 0 && item.visibility_level >= 0 &&
                              item.visibility_level < o.min_visibility_level);
    if (bad_quality) {
      ++result.rejected_quality;
      continue;
    }
    if (o.max_hash_distance >= 0 &&
        std::any_of(kept_hashes.begin(), kept_hashes.end(),
                    [&](uint64_t h) { return HammingDistance(h, item.phash) <= o.max_hash_distance; })) {
      ++result.rejected_duplicate;
      continue;
    }
    const std::string frame = item.kind == SourceKind::kLog ? item.source + "|" + item.frame_token : item.origin;
    const std::string instance = item.instance_token.empty() ? "" : item.source + "|" + item.instance_token;
    if ((o.max_per_frame > 0 && per_frame[frame] >= o.max_per_frame) ||
        (o.max_per_instance > 0 && !instance.empty() && per_instance[instance] >= o.max_per_instance)) {
      ++result.rejected_diversity;
      continue;
    }
    ++per_frame[frame];
    if (!instance.empty()) ++per_instance[instance];
    kept_hashes.push_back(item.phash);
    result.hits.push_back({c.row, c.score, ImageQuality(item), static_cast<int>(result.hits.size()) + 1});
  }
}

// Nearest-neighbour modes: search a growing candidate list until k hits survive the filters or every item
// has been ranked.
void SelectBySearch(const MiningIndex& index, VectorKind kind, const std::vector<float>& query, double min_score,
                    const QueryOptions& o, PromptResult& result) {
  size_t kk = std::min(index.size(), std::max<size_t>(static_cast<size_t>(o.k) * 8, 256));
  while (true) {
    const auto found = index.Search(kind, query.data(), 1, kk)[0];
    std::vector<Candidate> ranked;
    for (const SearchHit& h : found) ranked.push_back({h.row, h.score});
    Select(index, ranked, min_score, o, result);
    const bool exhausted_scores = !found.empty() && found.back().score < min_score;
    if (static_cast<int>(result.hits.size()) >= o.k || kk >= index.size() || exhausted_scores) return;
    kk = std::min(index.size(), kk * 4);
  }
}

}  // namespace

std::vector<PromptResult> RunQuery(const MiningIndex& index, const QueryOptions& o) {
  if (o.prompts.empty() && o.examples.empty()) throw InputError({}, "mine query: give --prompt or --example");
  if (o.k < 1) throw InputError({}, Msg() << "mine query: --k must be at least 1 (got " << o.k << ")");
  if (o.mode == QueryMode::kExample && o.examples.empty())
    throw InputError({}, "mine query: --mode example needs --example images");
  const bool clip_ready = index.has_clip() && o.clip != nullptr;
  if (o.clip && index.has_clip() && o.clip->Describe() != index.clip_model())
    throw InputError(index.dir(), Msg() << "was embedded with CLIP model '" << index.clip_model()
                                        << "', the query has '" << o.clip->Describe() << "'");
  if (o.mode == QueryMode::kClip && !clip_ready)
    throw InputError(index.dir(), index.has_clip() ? "clip mode needs the CLIP model the index was built with (--clip)"
                                                   : "has no CLIP embeddings: rebuild with --clip, or use --mode label");

  std::vector<PromptResult> results;
  const Lexicon names_only = Lexicon::Load("");
  size_t unserved = 0;  // prompts that named no category
  for (const std::string& prompt : o.prompts) {
    PromptResult r;
    r.prompt = prompt;
    if (o.mode == QueryMode::kExample)
      throw InputError({}, Msg() << "prompt '" << prompt << "' given with --mode example (examples are images)");
    const bool use_clip = o.mode == QueryMode::kClip || (o.mode == QueryMode::kAuto && clip_ready);
    if (use_clip) {
      r.mode = QueryMode::kClip;
      const auto text = o.clip->EmbedTexts({prompt});
      SelectBySearch(index, VectorKind::kClip, text[0], o.min_clip_score, o, r);
    } else {
      std::vector<std::string> categories;
      if (o.mode == QueryMode::kLabel) {
        r.mode = QueryMode::kLabel;
        if (std::string c = CategoryForPrompt(prompt); !c.empty()) categories.push_back(c);
        if (categories.empty())
          throw InputError({}, Msg() << "prompt '" << prompt << "' names no known category (`synthdrive categories` "
                                     << "lists them); --mode lexical reads synonyms and related nouns");
      } else {
        const LexicalMatch m = (o.lexicon ? *o.lexicon : names_only).Match(prompt);
        // A category's own name is a label query, whichever way auto reached it.
        r.mode = o.mode == QueryMode::kAuto && m.category_name ? QueryMode::kLabel : QueryMode::kLexical;
        for (const CategoryMatch& c : m.matches) {
          categories.push_back(c.category);
          r.why.push_back(c.chain);
        }
        if (categories.empty()) {
          r.why.push_back("'" + prompt + "' names no category (read as '" + m.head + "', " + m.how + ")" +
                          (o.lexicon && o.lexicon->has_wordnet() ? "" : "; WordNet is not installed (Debian's wordnet-base)") +
                          (index.has_clip() ? "" : "; the index has no CLIP embeddings for free-text search") +
                          ": try --example with photos of the object (mine query --example photo.jpg)");
          SD_LOG(Warn, r.why.back());
          ++unserved;
        }
        if (!categories.empty())
          for (const std::string& why : r.why) SD_LOG(Info, "\"" << prompt << "\": " << why);
      }
      for (const std::string& c : categories) r.category += (r.category.empty() ? "" : ",") + c;
      // Ranked from the shards' tables: a label query over a million items parses only the records it keeps.
      const std::set<std::string, std::less<>> wanted(categories.begin(), categories.end());  // found by string_view
      std::vector<std::pair<Candidate, double>> ranked_by_quality;
      for (size_t row = 0; row < index.size() && !wanted.empty(); ++row) {
        const ItemSummary s = index.summary(row);
        if (wanted.count(s.category)) ranked_by_quality.push_back({{row, 1.0}, ImageQuality(s)});
      }
      std::stable_sort(ranked_by_quality.begin(), ranked_by_quality.end(),
                       [](const auto& a, const auto& b) { return a.second > b.second; });
      std::vector<Candidate> ranked;
      ranked.reserve(ranked_by_quality.size());
      for (const auto& [c, quality] : ranked_by_quality) ranked.push_back(c);
      Select(index, ranked, 0.0, o, r);
    }
    SD_LOG(Info, "\"" << prompt << "\": " << ToString(r.mode) << " mode"
                      << (r.category.empty() ? "" : " (category " + r.category + ")") << ", " << r.hits.size()
                      << " hits of " << r.candidates << " candidates (rejected: " << r.rejected_score << " score, "
                      << r.rejected_quality << " quality, " << r.rejected_duplicate << " duplicates, "
                      << r.rejected_diversity << " diversity)");
    results.push_back(std::move(r));
  }
  if (!o.prompts.empty() && unserved == o.prompts.size() && o.examples.empty())
    throw InputError({}, Msg() << (o.prompts.size() == 1 ? "" : "no prompt names a category; the first: ")
                               << results.front().why.front());
  for (const fs::path& example : o.examples) {
    PromptResult r;
    r.prompt = example.string();
    const ImageU8 image = ReadImage(example);
    if (clip_ready && o.mode != QueryMode::kExample) {
      r.mode = QueryMode::kClip;
      SelectBySearch(index, VectorKind::kClip, o.clip->EmbedImages({image})[0], o.min_clip_score, o, r);
    } else {
      r.mode = QueryMode::kExample;
      SelectBySearch(index, VectorKind::kDescriptor, ImageDescriptor(image), o.min_example_score, o, r);
    }
    SD_LOG(Info, example.string() << ": " << ToString(r.mode) << " mode, " << r.hits.size() << " hits");
    results.push_back(std::move(r));
  }
  return results;
}

namespace {

std::string ContactSheet(const MiningIndex& index, const std::vector<PromptResult>& results) {
  std::ostringstream h;
  h << "<!doctype html><html><head><meta charset=\"utf-8\"><title>SynthDrive mining run</title><style>"
       "body{font-family:sans-serif;margin:16px;background:#fafafa}"
       ".grid{display:flex;flex-wrap:wrap;gap:10px}"
       ".hit{background:#fff;border:1px solid #ccc;padding:6px;width:200px;font-size:11px}"
       ".pair{display:flex;gap:2px}.pair img{width:98px;height:98px;object-fit:contain;background:#222}"
       "</style></head><body><h1>Mining run</h1>";
  for (const PromptResult& r : results) {
    h << "<h2>" << EscapeHtml(r.prompt) << "</h2>";
    for (const std::string& why : r.why) h << "<p><i>" << EscapeHtml(why) << "</i></p>";
    h << "<p>" << ToString(r.mode) << " mode"
      << (r.category.empty() ? "" : ", category " + EscapeHtml(r.category)) << "; " << r.hits.size() << " hits of "
      << r.candidates << " candidates; rejected " << r.rejected_score << " by score, " << r.rejected_quality
      << " by quality, " << r.rejected_duplicate << " as near-duplicates, " << r.rejected_diversity
      << " for diversity</p><div class=\"grid\">";
    for (const QueryHit& hit : r.hits) {
      const MinedItem& item = index.item(hit.row);
      const std::string where = item.kind == SourceKind::kLog ? item.frame_token + " " + item.camera
                                                              : fs::path(item.origin).filename().string();
      h << "<div class=\"hit\"><div class=\"pair\"><img src=\"crops/" << item.id << ".jpg\" loading=\"lazy\">";
      if (!item.mask_file.empty()) h << "<img src=\"masks/" << item.id << ".png\" loading=\"lazy\">";
      h << "</div>#" << hit.rank << " score " << Fixed(hit.score, 3) << " quality " << Fixed(hit.quality, 2)
        << "<br>" << EscapeHtml(item.category.empty() ? "(no label)" : item.category) << " · "
        << static_cast<int>(ObjectSizePx(item)) << " px · sharp " << static_cast<int>(item.sharpness)
        << "<br>trunc " << Fixed(item.truncation, 2) << " · occl " << Fixed(item.occlusion, 2) << " · mask "
        << EscapeHtml(item.mask_source.empty() ? "none" : item.mask_source) << "<br>" << EscapeHtml(where)
        << "</div>";
    }
    h << "</div>";
  }
  h << "</body></html>\n";
  return h.str();
}

}  // namespace

void WriteMiningRun(const fs::path& run_dir, const MiningIndex& index, const std::vector<PromptResult>& results,
                    const QueryOptions& o, bool overwrite) {
  StagingDirectory staging(run_dir, overwrite);
  const fs::path out = staging.path();
  fs::create_directories(out / "crops");
  fs::create_directories(out / "masks");
  std::string manifest;
  std::set<size_t> copied;
  json prompts = json::array();
  for (const PromptResult& r : results) {
    for (const QueryHit& hit : r.hits) {
      MinedItem item = index.item(hit.row);
      const fs::path from = index.ItemDir(hit.row);
      const std::string crop = "crops/" + item.id + ".jpg";
      const std::string mask = item.mask_file.empty() ? "" : "masks/" + item.id + ".png";
      if (copied.insert(hit.row).second) {
        fs::copy_file(from / item.crop_file, out / crop, fs::copy_options::overwrite_existing);
        if (!mask.empty()) fs::copy_file(from / item.mask_file, out / mask, fs::copy_options::overwrite_existing);
      }
      item.crop_file = crop;
      item.mask_file = mask;
      json j = ToJson(item);
      j["prompt"] = r.prompt;
      j["mode"] = ToString(r.mode);
      j["score"] = hit.score;
      j["quality"] = hit.quality;
      j["rank"] = hit.rank;
      manifest += j.dump() + "\n";
    }
    prompts.push_back({{"prompt", r.prompt},
                       {"mode", ToString(r.mode)},
                       {"category", r.category},
                       {"why", r.why},
                       {"hits", r.hits.size()},
                       {"candidates", r.candidates},
                       {"rejected", {{"score", r.rejected_score},
                                     {"quality", r.rejected_quality},
                                     {"duplicate", r.rejected_duplicate},
                                     {"diversity", r.rejected_diversity}}}});
  }
  WriteFileAtomic(out / "manifest.jsonl", manifest);
  WriteJsonFile(out / "run.json",
                {{"index", fs::absolute(index.dir()).string()},
                 {"index_items", index.size()},
                 {"clip_model", index.clip_model()},
                 {"k", o.k},
                 {"filters", {{"min_clip_score", o.min_clip_score},
                              {"min_example_score", o.min_example_score},
                              {"min_size_px", o.min_size_px},
                              {"max_truncation", o.max_truncation},
                              {"max_occlusion", o.max_occlusion},
                              {"min_sharpness", o.min_sharpness},
                              {"min_visibility_level", o.min_visibility_level},
                              {"max_hash_distance", o.max_hash_distance},
                              {"max_per_frame", o.max_per_frame},
                              {"max_per_instance", o.max_per_instance}}},
                 {"prompts", prompts}});
  WriteFileAtomic(out / "index.html", ContactSheet(index, results));
  staging.Commit();
}

std::vector<ManifestEntry> ReadManifest(const fs::path& manifest_jsonl) {
  const fs::path dir = fs::absolute(manifest_jsonl).parent_path();
  std::vector<ManifestEntry> entries;
  ForEachJsonLine(manifest_jsonl, [&](const json& j, const std::string& where) {
    ManifestEntry e;
    e.item = ItemFromJson(j, where);
    const JsonReader r(j, where);
    e.prompt = r.StringOr("prompt", "");
    e.mode = r.StringOr("mode", "");
    e.score = r.NumberOr("score", 0);
    e.quality = r.NumberOr("quality", 0);
    e.rank = static_cast<int>(r.NumberOr("rank", 0));
    for (std::string* file : {&e.item.crop_file, &e.item.mask_file}) {
      if (file->empty()) continue;
      const fs::path p = dir / *file;
      if (!fs::exists(p)) throw InputError(where, Msg() << "names " << *file << ", which does not exist in " << dir.string());
      *file = p.string();
    }
    entries.push_back(std::move(e));
  });
  return entries;
}

}  // namespace sd::mining
