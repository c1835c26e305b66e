#pragma once
// The asset bank (DESIGN.md "bank"; docs/bank.md): a catalogue of asset folders in one SQLite file, so synth
// and people can find assets by category, real size, provenance, quality and (with CLIP) text, and so a batch
// can check that nothing it depends on has changed on disk.
//
// The bank references folders by absolute path and never copies them. For each folder it records asset.json's
// fields (category, extent in metres, source, licence, attribution, stages, quality), every regular file
// under the folder (relative path, size, SHA-256) and, when a CLIP encoder is given, the unit CLIP embedding of
// preview.png.
//
// Guarantees: every change is one SQLite transaction (a process killed mid-add leaves the catalogue as it was);
// the file is in WAL mode with a busy timeout, so several processes may add to one bank at once. WAL needs a
// local file system (or one with working POSIX locks and shared memory): not NFS.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "models/clip.h"

namespace sd::bank {

// The bank file when none is named: $SYNTHDRIVE_BANK, else ./bank.sqlite.
std::filesystem::path DefaultBankPath();

struct BankFile {
  std::string path;  // relative to the asset folder, '/' separated
  int64_t size = 0;
  std::string sha256;  // lowercase hex
};

struct BankEntry {
  std::string id, name, category;
  std::filesystem::path dir;  // absolute
  Eigen::Vector3d extent = Eigen::Vector3d::Zero();  // length, width, height, metres
  std::string source, licence, attribution;
  nlohmann::json stages = nlohmann::json::array();
  nlohmann::json quality = nlohmann::json::object();
  std::string added_at;  // UTC, ISO 8601
  std::string clip_model;           // ClipEncoder::Describe() of the embedding's model; empty without one
  std::vector<float> clip_embedding;  // unit norm; empty without one
  std::vector<BankFile> files;        // sorted by path
  std::optional<float> score;         // text queries: cosine similarity to the text
};

// Everything a query can filter on; unset fields do not filter. Results are sorted by id, or by descending
// text similarity when `text` is set.
struct BankQuery {
  std::string category;
  std::optional<Eigen::Vector3d> min_extent, max_extent;  // per axis, metres, inclusive
  std::string text;  // needs a CLIP encoder; ranks the entries that have embeddings of its dimension
  std::map<std::string, double> min_quality, max_quality;  // asset.json "quality" figures; a missing one fails
  size_t limit = 0;  // 0: all
};

// A query as JSON, so a scenario can name assets by query instead of by path:
//   {"bank": "assets.sqlite", "category": "traffic_cone", "min_extent": [0.2, 0.2, 0.5],
//    "max_extent": [1, 1, 1.2], "text": "red cone", "min_quality": {"views": 6},
//    "max_quality": {"refine_final_loss_normal": 0.2}, "limit": 10}
// Every key is optional; unknown keys are refused (a typo must not silently widen the query). `bank`, when
// present and relative, is resolved against the directory of `where` and returned in *bank_path.
// InputError("<where>: <json path>: <problem>") for a bad value.
BankQuery BankQueryFromJson(const nlohmann::json& j, const std::filesystem::path& where,
                            std::filesystem::path* bank_path = nullptr);
nlohmann::json BankEntryToJson(const BankEntry& e, bool with_files);

// The bar a generated asset must clear to enter the bank, on its asset.json quality figures (assetgen/asset.h
// namespace quality). A figure the asset does not carry is not checked: an imported mesh has no held-out view, a
// photo asset no LiDAR returns.
struct QualityGate {
  std::map<std::string, double> min, max;
};
// watertight >= 1, heldout_silhouette_iou >= 0.5, lidar_p2m_median_m <= 0.05, real_texture_fraction >= 0.15,
// extent_to_size_max <= 1.3: an asset below them would teach a detector the asset's defects (a hole, a silhouette
// the camera never showed, a surface off its own returns, a texture mostly invented, a shape not the object's).
QualityGate DefaultQualityGate();
// "NAME>=VALUE" or "NAME<=VALUE" into the gate (replacing that side of NAME); InputError naming `option` otherwise.
void ParseGateRule(const std::string& rule, const std::string& option, QualityGate* gate);
// The first figure that fails, as "heldout_silhouette_iou 0.42 < 0.5"; nullopt when all pass.
std::optional<std::string> GateFailure(const nlohmann::json& quality, const QualityGate& gate);

struct AddOptions {
  bool replace = false;                           // replace an entry of the same id whose files differ
  const QualityGate* gate = nullptr;              // refuse assets below it (InputError naming the figure)
  const models::ClipEncoder* clip = nullptr;       // embed preview.png when set
  std::function<void()> inside_transaction;        // test hook: runs after the rows are written, before commit
};

enum class AddStatus { kAdded, kUnchanged, kReplaced };
struct AddResult {
  std::string id;
  AddStatus status = AddStatus::kAdded;
};

struct VerifyProblem {
  std::string id;
  std::string path;  // the file (absolute), or the folder for loadability problems
  std::string what;  // "missing", "size changed ...", "SHA-256 changed", "not loadable: ..."
};
struct VerifyReport {
  size_t entries = 0, files = 0;
  std::vector<VerifyProblem> problems;
};

class Bank {
 public:
  // Opens (with `create`, creates) the bank file. InputError for a missing file without `create`, or a file
  // that is not a SynthDrive bank.
  static Bank Open(const std::filesystem::path& path, bool create);
  Bank(Bank&&) noexcept;
  Bank& operator=(Bank&&) noexcept;
  ~Bank();

  const std::filesystem::path& path() const { return path_; }

  // Catalogues an asset folder (LoadAsset must accept it). Same id already present: identical folder and file
  // hashes -> kUnchanged (reruns are no-ops); otherwise InputError unless options.replace.
  AddResult Add(const std::filesystem::path& asset_dir, const AddOptions& options = {});
  // Needs `clip` when query.text is set (InputError otherwise).
  std::vector<BankEntry> Query(const BankQuery& query, const models::ClipEncoder* clip = nullptr) const;
  // InputError for an unknown id.
  BankEntry Show(const std::string& id) const;
  // Re-hashes every catalogued file and loads every asset (or only `ids`). Unknown ids are InputError.
  VerifyReport Verify(const std::vector<std::string>& ids = {}) const;
  // Removes the entry; with delete_files also its folder (only when its asset.json still names this id).
  void Remove(const std::string& id, bool delete_files);

 private:
  struct Db;
  Bank() = default;
  std::unique_ptr<Db> db_;
  std::filesystem::path path_;
};

// SHA-256 of a file, lowercase hex. InputError naming the file when unreadable.
std::string Sha256File(const std::filesystem::path& path);

}  // namespace sd::bank
