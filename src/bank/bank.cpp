#include "bank/bank.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <set>

#include <openssl/evp.h>
#include <sqlite3.h>

#include "assetgen/asset.h"
#include "core/error.h"
#include "core/log.h"
#include "io/image_io.h"
#include "io/json.h"

namespace sd::bank {
namespace fs = std::filesystem;

namespace {

// Bumped when the schema changes; an older program refuses a newer bank instead of misreading it.
constexpr int kSchemaVersion = 1;
constexpr const char* kFormat = "synthdrive-bank";
// Long enough for another process's add (hashing happens before the transaction, so writers hold the lock
// only for a few inserts); a bank busy for a minute is an error worth reporting.
constexpr int kBusyTimeoutMs = 60000;

constexpr const char* kSchema = R"sql(
CREATE TABLE bank_meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE assets(
  id TEXT PRIMARY KEY,
  dir TEXT NOT NULL,
  name TEXT NOT NULL,
  category TEXT NOT NULL,
  extent_x REAL NOT NULL, extent_y REAL NOT NULL, extent_z REAL NOT NULL,
  source TEXT NOT NULL, licence TEXT NOT NULL, attribution TEXT NOT NULL,
  stages TEXT NOT NULL,
  quality TEXT NOT NULL,
  clip_model TEXT NOT NULL DEFAULT '',
  clip_embedding BLOB,
  added_at TEXT NOT NULL);
CREATE INDEX assets_category ON assets(category);
CREATE TABLE files(
  asset_id TEXT NOT NULL REFERENCES assets(id) ON DELETE CASCADE,
  path TEXT NOT NULL,
  size INTEGER NOT NULL,
  sha256 TEXT NOT NULL,
  PRIMARY KEY(asset_id, path));
)sql";

}  // namespace

// The connection and small statement helpers. Every SQLite failure becomes an InputError naming the bank file:
// the causes (locked past the timeout, disk full, a corrupt or foreign file) are all about the file.
struct BankConnection {
  sqlite3* db = nullptr;
  fs::path path;

  BankConnection() = default;
  BankConnection(const BankConnection&) = delete;
  BankConnection& operator=(const BankConnection&) = delete;
  ~BankConnection() {
    if (db) sqlite3_close_v2(db);
  }
  [[noreturn]] void Fail(const std::string& what) const {
    throw InputError(path, Msg() << what << ": " << (db ? sqlite3_errmsg(db) : "cannot open"));
  }
  void Exec(const char* sql) const {
    char* err = nullptr;
    if (sqlite3_exec(db, sql, nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string msg = err ? err : sqlite3_errmsg(db);
      sqlite3_free(err);
      throw InputError(path, Msg() << "SQLite: " << msg);
    }
  }
};
struct Bank::Db : BankConnection {};

namespace {

class Stmt {
 public:
  Stmt(const BankConnection& db, const char* sql) : db_(db) {
    if (sqlite3_prepare_v2(db.db, sql, -1, &stmt_, nullptr) != SQLITE_OK) db.Fail("SQLite");
  }
  ~Stmt() { sqlite3_finalize(stmt_); }
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;

  Stmt& Bind(int i, const std::string& s) {
    Check(sqlite3_bind_text(stmt_, i, s.data(), static_cast<int>(s.size()), SQLITE_TRANSIENT));
    return *this;
  }
  Stmt& Bind(int i, double v) {
    Check(sqlite3_bind_double(stmt_, i, v));
    return *this;
  }
  Stmt& Bind(int i, int64_t v) {
    Check(sqlite3_bind_int64(stmt_, i, v));
    return *this;
  }
  Stmt& BindBlob(int i, const void* data, size_t bytes) {
    if (bytes == 0)
      Check(sqlite3_bind_null(stmt_, i));
    else
      Check(sqlite3_bind_blob(stmt_, i, data, static_cast<int>(bytes), SQLITE_TRANSIENT));
    return *this;
  }
  // True while there is a row.
  bool Step() {
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    db_.Fail("SQLite");
  }
  void Run() {
    while (Step()) {
    }
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }
  std::string Text(int col) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(stmt_, col));
    return p ? std::string(p, static_cast<size_t>(sqlite3_column_bytes(stmt_, col))) : std::string();
  }
  double Double(int col) const { return sqlite3_column_double(stmt_, col); }
  int64_t Int(int col) const { return sqlite3_column_int64(stmt_, col); }
  std::vector<float> Floats(int col) const {
    const void* p = sqlite3_column_blob(stmt_, col);
    const int bytes = sqlite3_column_bytes(stmt_, col);
    std::vector<float> v(static_cast<size_t>(bytes) / sizeof(float));
    if (p && !v.empty()) std::memcpy(v.data(), p, v.size() * sizeof(float));
    return v;
  }

 private:
  void Check(int rc) const {
    if (rc != SQLITE_OK) db_.Fail("SQLite bind");
  }
  const BankConnection& db_;
  sqlite3_stmt* stmt_ = nullptr;
};

// BEGIN IMMEDIATE takes the write lock up front (waiting up to the busy timeout), so a transaction never has
// to upgrade a read lock mid-way — the case where SQLite gives up at once with SQLITE_BUSY instead of waiting.
class Transaction {
 public:
  explicit Transaction(const BankConnection& db) : db_(db) { db_.Exec("BEGIN IMMEDIATE"); }
  ~Transaction() {
    if (!done_) sqlite3_exec(db_.db, "ROLLBACK", nullptr, nullptr, nullptr);
  }
  void Commit() {
    db_.Exec("COMMIT");
    done_ = true;
  }

 private:
  const BankConnection& db_;
  bool done_ = false;
};

std::string Hex(const unsigned char* p, size_t n) {
  static const char* digits = "0123456789abcdef";
  std::string s(2 * n, '0');
  for (size_t i = 0; i < n; ++i) {
    s[2 * i] = digits[p[i] >> 4];
    s[2 * i + 1] = digits[p[i] & 15];
  }
  return s;
}

// Every regular file under the folder, sorted by relative path.
std::vector<BankFile> HashFolder(const fs::path& dir) {
  std::vector<BankFile> files;
  try {
    for (const fs::directory_entry& e : fs::recursive_directory_iterator(dir)) {
      if (!e.is_regular_file()) continue;
      BankFile f;
      f.path = e.path().lexically_relative(dir).generic_string();
      f.size = static_cast<int64_t>(e.file_size());
      f.sha256 = Sha256File(e.path());
      files.push_back(std::move(f));
    }
  } catch (const fs::filesystem_error& e) {  // unreadable subfolder: about this input, not a program bug
    throw InputError(e.path1().empty() ? dir : e.path1(), e.code().message());
  }
  std::sort(files.begin(), files.end(), [](const BankFile& a, const BankFile& b) { return a.path < b.path; });
  return files;
}

bool SameFiles(const std::vector<BankFile>& a, const std::vector<BankFile>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].path != b[i].path || a[i].size != b[i].size || a[i].sha256 != b[i].sha256) return false;
  return true;
}

std::vector<BankFile> LoadFiles(const BankConnection& db, const std::string& id) {
  Stmt s(db, "SELECT path, size, sha256 FROM files WHERE asset_id = ? ORDER BY path");
  s.Bind(1, id);
  std::vector<BankFile> files;
  while (s.Step()) files.push_back({s.Text(0), s.Int(1), s.Text(2)});
  return files;
}

constexpr const char* kEntryColumns =
    "id, dir, name, category, extent_x, extent_y, extent_z, source, licence, attribution, stages, quality, "
    "clip_model, clip_embedding, added_at";

BankEntry ReadEntry(const Stmt& s) {
  BankEntry e;
  e.id = s.Text(0);
  e.dir = s.Text(1);
  e.name = s.Text(2);
  e.category = s.Text(3);
  e.extent = {s.Double(4), s.Double(5), s.Double(6)};
  e.source = s.Text(7);
  e.licence = s.Text(8);
  e.attribution = s.Text(9);
  e.stages = nlohmann::json::parse(s.Text(10), nullptr, false);
  e.quality = nlohmann::json::parse(s.Text(11), nullptr, false);
  e.clip_model = s.Text(12);
  e.clip_embedding = s.Floats(13);
  e.added_at = s.Text(14);
  return e;
}

// A quality figure named `key` that is a number; nullopt when absent or not a number.
std::optional<double> QualityFigure(const nlohmann::json& quality, const std::string& key) {
  if (!quality.is_object() || !quality.contains(key) || !quality.at(key).is_number()) return std::nullopt;
  return quality.at(key).get<double>();
}

}  // namespace

QualityGate DefaultQualityGate() {
  QualityGate g;
  g.min = {{quality::kWatertight, 1.0}, {quality::kHeldOutSilhouetteIou, 0.5}, {quality::kRealTextureFraction, 0.15}};
  g.max = {{quality::kLidarPointToMeshMedianM, 0.05}, {quality::kExtentToSize, 1.3}};
  return g;
}

void ParseGateRule(const std::string& rule, const std::string& option, QualityGate* gate) {
  for (const char* op : {">=", "<="}) {
    const size_t at = rule.find(op);
    if (at == std::string::npos || at == 0) continue;
    try {
      size_t used = 0;
      const std::string number = rule.substr(at + 2);
      const double v = std::stod(number, &used);
      if (used != number.size() || !std::isfinite(v)) throw std::invalid_argument("trailing text");
      (op[0] == '>' ? gate->min : gate->max)[rule.substr(0, at)] = v;
      return;
    } catch (const std::exception&) {
      break;
    }
  }
  throw InputError({}, Msg() << option << " '" << rule << "': expected NAME>=NUMBER or NAME<=NUMBER");
}

std::optional<std::string> GateFailure(const nlohmann::json& quality, const QualityGate& gate) {
  for (const auto& [key, min] : gate.min)
    if (const auto v = QualityFigure(quality, key); v && *v < min) return Msg() << key << " " << *v << " < " << min;
  for (const auto& [key, max] : gate.max)
    if (const auto v = QualityFigure(quality, key); v && *v > max) return Msg() << key << " " << *v << " > " << max;
  return std::nullopt;
}

fs::path DefaultBankPath() {
  if (const char* env = std::getenv("SYNTHDRIVE_BANK"); env && *env) return env;
  return "bank.sqlite";
}

std::string Sha256File(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot read");
  std::unique_ptr<EVP_MD_CTX, void (*)(EVP_MD_CTX*)> ctx(EVP_MD_CTX_new(), EVP_MD_CTX_free);
  SD_CHECK(ctx && EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) == 1, << "OpenSSL SHA-256 init");
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const std::streamsize n = in.gcount();
    if (n > 0) SD_CHECK(EVP_DigestUpdate(ctx.get(), buf.data(), static_cast<size_t>(n)) == 1, << "OpenSSL");
  }
  if (in.bad()) throw InputError(path, "read error");
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  SD_CHECK(EVP_DigestFinal_ex(ctx.get(), md, &len) == 1, << "OpenSSL");
  return Hex(md, len);
}

Bank::Bank(Bank&&) noexcept = default;
Bank& Bank::operator=(Bank&&) noexcept = default;
Bank::~Bank() = default;

Bank Bank::Open(const fs::path& path, bool create) {
  const bool exists = fs::exists(path);
  if (!exists && !create) throw InputError(path, "no bank here (`synthdrive bank add` creates one)");
  if (exists && fs::is_directory(path)) throw InputError(path, "is a directory, not a bank file");
  if (exists && fs::file_size(path) > 0) {
    // A foreign file must be refused before SQLite touches it (opening in WAL mode would add -wal/-shm files).
    char header[16] = {};
    std::ifstream in(path, std::ios::binary);
    in.read(header, sizeof(header));
    if (std::memcmp(header, "SQLite format 3", 16) != 0)
      throw InputError(path, "not a SynthDrive bank (not an SQLite file)");
  }
  if (!exists && !path.parent_path().empty()) fs::create_directories(path.parent_path());
  Bank bank;
  bank.path_ = path;
  bank.db_ = std::make_unique<Db>();
  Db& d = *bank.db_;
  d.path = path;
  const int flags = SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0) | SQLITE_OPEN_NOMUTEX;
  if (sqlite3_open_v2(path.c_str(), &d.db, flags, nullptr) != SQLITE_OK) d.Fail("cannot open");
  sqlite3_busy_timeout(d.db, kBusyTimeoutMs);
  // WAL: readers never block the writer and a killed writer leaves only an uncommitted tail that the next
  // opener discards. synchronous=FULL also makes a committed add survive power loss.
  d.Exec("PRAGMA journal_mode=WAL");
  d.Exec("PRAGMA synchronous=FULL");
  d.Exec("PRAGMA foreign_keys=ON");

  Transaction t(d);
  bool has_meta = false;
  int64_t tables = 0;
  {
    Stmt s(d, "SELECT name FROM sqlite_master WHERE type = 'table'");
    while (s.Step()) {
      ++tables;
      if (s.Text(0) == "bank_meta") has_meta = true;
    }
  }
  if (has_meta) {
    std::map<std::string, std::string> meta;
    Stmt s(d, "SELECT key, value FROM bank_meta");
    while (s.Step()) meta[s.Text(0)] = s.Text(1);
    if (meta["format"] != kFormat) throw InputError(path, "not a SynthDrive bank (bank_meta has another format)");
    const int version = std::atoi(meta["schema_version"].c_str());
    if (version != kSchemaVersion)
      throw InputError(path, Msg() << "bank schema version " << version << "; this program reads version "
                                   << kSchemaVersion);
  } else if (tables > 0 || !create) {
    throw InputError(path, "not a SynthDrive bank (an SQLite file without the bank tables)");
  } else {
    d.Exec(kSchema);
    Stmt s(d, "INSERT INTO bank_meta(key, value) VALUES (?, ?)");
    s.Bind(1, std::string("format")).Bind(2, std::string(kFormat)).Run();
    s.Bind(1, std::string("schema_version")).Bind(2, std::to_string(kSchemaVersion)).Run();
  }
  t.Commit();
  return bank;
}

AddResult Bank::Add(const fs::path& asset_dir, const AddOptions& options) {
  fs::path dir = fs::absolute(asset_dir).lexically_normal();
  if (!fs::is_directory(dir) && dir.filename() == "asset.json") dir = dir.parent_path();
  if (!fs::exists(dir)) throw InputError(asset_dir, "no such folder");
  dir = fs::canonical(dir);
  const Asset asset = LoadAsset(dir);  // the bank holds only assets synth can use
  const AssetInfo& info = asset.info;
  if (options.gate)
    if (const auto failed = GateFailure(info.quality, *options.gate))
      throw InputError(dir / "asset.json", "below the bank's quality gate: " + *failed +
                                               " (bank add --gate NAME>=VALUE or --no-gate to change it)");
  // Hashing and embedding happen before the transaction, so the write lock is held only for the inserts.
  const std::vector<BankFile> files = HashFolder(dir);
  std::vector<float> embedding;
  if (options.clip) {
    const fs::path preview = dir / "preview.png";
    if (!fs::exists(preview)) throw InputError(preview, "missing (the CLIP embedding is of the preview)");
    embedding = options.clip->EmbedImages(std::vector<ImageU8>{ReadImage(preview)}).at(0);
  }
  const std::string clip_model = options.clip ? options.clip->Describe() : std::string();

  Transaction t(*db_);
  AddResult result;
  result.id = info.id;
  {
    Stmt s(*db_, "SELECT dir, clip_model, length(clip_embedding) FROM assets WHERE id = ?");
    s.Bind(1, info.id);
    if (s.Step()) {
      const std::string old_dir = s.Text(0);
      const bool has_embedding = s.Int(2) > 0;
      if (old_dir == dir.string() && SameFiles(LoadFiles(*db_, info.id), files)) {
        // A rerun: nothing to do, except record an embedding the first add did not compute.
        if (options.clip && (!has_embedding || s.Text(1) != clip_model)) {
          Stmt u(*db_, "UPDATE assets SET clip_model = ?, clip_embedding = ? WHERE id = ?");
          u.Bind(1, clip_model).BindBlob(2, embedding.data(), embedding.size() * sizeof(float)).Bind(3, info.id).Run();
        }
        if (options.inside_transaction) options.inside_transaction();
        t.Commit();
        result.status = AddStatus::kUnchanged;
        return result;
      }
      if (!options.replace)
        throw InputError(dir, Msg() << "asset id '" << info.id << "' is already in the bank "
                                    << (old_dir == dir.string() ? std::string("with other file contents")
                                                                : "from " + old_dir)
                                    << " (--replace replaces it)");
      result.status = AddStatus::kReplaced;
    }
  }
  if (result.status == AddStatus::kReplaced) {
    Stmt del(*db_, "DELETE FROM assets WHERE id = ?");
    del.Bind(1, info.id).Run();
  }
  {
    Stmt ins(*db_,
             "INSERT INTO assets(id, dir, name, category, extent_x, extent_y, extent_z, source, licence, attribution, "
             "stages, quality, clip_model, clip_embedding, added_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, "
             "strftime('%Y-%m-%dT%H:%M:%SZ', 'now'))");
    ins.Bind(1, info.id).Bind(2, dir.string()).Bind(3, info.name).Bind(4, info.category);
    ins.Bind(5, info.extent.x()).Bind(6, info.extent.y()).Bind(7, info.extent.z());
    ins.Bind(8, info.source).Bind(9, info.licence).Bind(10, info.attribution);
    ins.Bind(11, info.stages.dump()).Bind(12, info.quality.dump()).Bind(13, clip_model);
    ins.BindBlob(14, embedding.data(), embedding.size() * sizeof(float));
    ins.Run();
  }
  {
    Stmt ins(*db_, "INSERT INTO files(asset_id, path, size, sha256) VALUES (?, ?, ?, ?)");
    for (const BankFile& f : files) ins.Bind(1, info.id).Bind(2, f.path).Bind(3, f.size).Bind(4, f.sha256).Run();
  }
  if (options.inside_transaction) options.inside_transaction();
  t.Commit();
  return result;
}

std::vector<BankEntry> Bank::Query(const BankQuery& q, const models::ClipEncoder* clip) const {
  std::vector<float> text;
  if (!q.text.empty()) {
    if (!clip) throw InputError(path_, Msg() << "text query '" << q.text << "' needs a CLIP model (--clip)");
    text = clip->EmbedTexts({q.text}).at(0);
  }
  std::string sql = std::string("SELECT ") + kEntryColumns + " FROM assets WHERE 1";
  if (!q.category.empty()) sql += " AND category = ?1";
  const char* axes[3] = {"extent_x", "extent_y", "extent_z"};
  for (int k = 0; k < 3; ++k) {
    if (q.min_extent) sql += Msg() << " AND " << axes[k] << " >= ?" << (2 + k);
    if (q.max_extent) sql += Msg() << " AND " << axes[k] << " <= ?" << (5 + k);
  }
  sql += " ORDER BY id";
  Stmt s(*db_, sql.c_str());
  if (!q.category.empty()) s.Bind(1, q.category);
  for (int k = 0; k < 3; ++k) {
    if (q.min_extent) s.Bind(2 + k, (*q.min_extent)[k]);
    if (q.max_extent) s.Bind(5 + k, (*q.max_extent)[k]);
  }
  std::vector<BankEntry> out;
  size_t with_embedding = 0;
  while (s.Step()) {
    BankEntry e = ReadEntry(s);
    bool keep = true;
    for (const auto& [key, min] : q.min_quality) {
      const auto v = QualityFigure(e.quality, key);
      keep = keep && v && *v >= min;
    }
    for (const auto& [key, max] : q.max_quality) {
      const auto v = QualityFigure(e.quality, key);
      keep = keep && v && *v <= max;
    }
    if (!text.empty()) {
      if (e.clip_embedding.size() != text.size()) continue;
      ++with_embedding;
      e.score = models::ClipEncoder::Similarity(text, e.clip_embedding);
    }
    if (keep) out.push_back(std::move(e));
  }
  if (!text.empty()) {
    if (with_embedding == 0)
      throw InputError(path_, Msg() << "text query: no matching entry has a CLIP embedding of dimension "
                                    << text.size() << " (add assets with --clip)");
    std::stable_sort(out.begin(), out.end(),
                     [](const BankEntry& a, const BankEntry& b) { return *a.score > *b.score; });
  }
  if (q.limit > 0 && out.size() > q.limit) out.resize(q.limit);
  return out;
}

BankEntry Bank::Show(const std::string& id) const {
  Stmt s(*db_, (std::string("SELECT ") + kEntryColumns + " FROM assets WHERE id = ?").c_str());
  s.Bind(1, id);
  if (!s.Step()) throw InputError(path_, Msg() << "no asset '" << id << "' in the bank");
  BankEntry e = ReadEntry(s);
  e.files = LoadFiles(*db_, id);
  return e;
}

VerifyReport Bank::Verify(const std::vector<std::string>& ids) const {
  std::vector<BankEntry> entries;
  if (ids.empty()) {
    // One read transaction, so the list and the file rows agree even while others add.
    db_->Exec("BEGIN");
    try {
      for (BankEntry& e : Query({})) {
        e.files = LoadFiles(*db_, e.id);
        entries.push_back(std::move(e));
      }
    } catch (...) {
      sqlite3_exec(db_->db, "ROLLBACK", nullptr, nullptr, nullptr);
      throw;
    }
    db_->Exec("COMMIT");
  } else {
    for (const std::string& id : ids) entries.push_back(Show(id));
  }
  VerifyReport report;
  for (const BankEntry& e : entries) {
    ++report.entries;
    for (const BankFile& f : e.files) {
      ++report.files;
      const fs::path p = e.dir / f.path;
      std::error_code ec;
      if (!fs::is_regular_file(p, ec)) {
        report.problems.push_back({e.id, p.string(), "missing"});
        continue;
      }
      const auto size = static_cast<int64_t>(fs::file_size(p, ec));
      if (size != f.size) {
        report.problems.push_back(
            {e.id, p.string(), Msg() << "size changed (catalogued " << f.size << " bytes, now " << size << ")"});
        continue;
      }
      try {
        if (Sha256File(p) != f.sha256) report.problems.push_back({e.id, p.string(), "SHA-256 changed"});
      } catch (const InputError& err) {
        report.problems.push_back({e.id, p.string(), Msg() << "unreadable: " << err.what()});
      }
    }
    try {
      (void)LoadAsset(e.dir);
    } catch (const std::exception& err) {
      report.problems.push_back({e.id, e.dir.string(), Msg() << "not loadable: " << err.what()});
    }
  }
  return report;
}

void Bank::Remove(const std::string& id, bool delete_files) {
  fs::path dir;
  {
    Transaction t(*db_);
    {
      Stmt s(*db_, "SELECT dir FROM assets WHERE id = ?");
      s.Bind(1, id);
      if (!s.Step()) throw InputError(path_, Msg() << "no asset '" << id << "' in the bank");
      dir = s.Text(0);
    }
    Stmt del(*db_, "DELETE FROM assets WHERE id = ?");
    del.Bind(1, id).Run();
    t.Commit();
  }
  if (!delete_files) return;
  // Delete only what is still this asset's folder: a folder since reused for something else stays.
  const fs::path json = dir / "asset.json";
  std::string on_disk;
  try {
    on_disk = ReadJsonFile(json).value("id", std::string());
  } catch (const InputError&) {
  }
  if (on_disk != id) {
    SD_LOG(Warn, dir.string() << ": not deleted (its asset.json no longer names '" << id << "')");
    return;
  }
  fs::remove_all(dir);
}

BankQuery BankQueryFromJson(const nlohmann::json& j, const fs::path& where, fs::path* bank_path) {
  const JsonReader r(j, where);
  if (!j.is_object()) r.Fail("a bank query must be a JSON object");
  static const std::set<std::string> known = {"bank",        "category",    "min_extent", "max_extent",
                                              "text",        "min_quality", "max_quality", "limit"};
  for (const auto& [key, value] : j.items())
    if (!known.count(key))
      r.Fail(Msg() << "unknown key '" << key
                   << "' (known: bank, category, min_extent, max_extent, text, min_quality, max_quality, limit)");
  BankQuery q;
  q.category = r.StringOr("category", "");
  q.text = r.StringOr("text", "");
  auto extent = [&](const char* key) -> std::optional<Eigen::Vector3d> {
    if (!r.Has(key)) return std::nullopt;
    const JsonReader e = r[key];
    if (e.Size() != 3) e.Fail("expected [length, width, height] in metres");
    return Eigen::Vector3d(e[0].Number(), e[1].Number(), e[2].Number());
  };
  q.min_extent = extent("min_extent");
  q.max_extent = extent("max_extent");
  auto figures = [&](const char* key, std::map<std::string, double>& out) {
    if (!r.Has(key)) return;
    const JsonReader f = r[key];
    if (!f.raw().is_object()) f.Fail("expected an object of quality figure -> number");
    for (const auto& [name, value] : f.raw().items()) out[name] = f[name].Number();
  };
  figures("min_quality", q.min_quality);
  figures("max_quality", q.max_quality);
  if (r.Has("limit")) {
    const int64_t limit = r["limit"].Integer();
    if (limit < 0) r["limit"].Fail("must be >= 0");
    q.limit = static_cast<size_t>(limit);
  }
  if (bank_path) {
    *bank_path = fs::path();
    if (r.Has("bank")) {
      fs::path p = r["bank"].String();
      if (p.is_relative() && !where.empty()) p = where.parent_path() / p;
      *bank_path = p;
    }
  }
  return q;
}

nlohmann::json BankEntryToJson(const BankEntry& e, bool with_files) {
  nlohmann::json j;
  j["id"] = e.id;
  j["name"] = e.name;
  j["category"] = e.category;
  j["dir"] = e.dir.string();
  j["extent_m"] = {e.extent.x(), e.extent.y(), e.extent.z()};
  j["source"] = e.source;
  j["licence"] = e.licence;
  j["attribution"] = e.attribution;
  j["stages"] = e.stages;
  j["quality"] = e.quality;
  j["added_at"] = e.added_at;
  j["clip_model"] = e.clip_model.empty() ? nlohmann::json() : nlohmann::json(e.clip_model);
  j["has_clip_embedding"] = !e.clip_embedding.empty();
  if (e.score) j["score"] = *e.score;
  if (with_files) {
    j["files"] = nlohmann::json::array();
    for (const BankFile& f : e.files) j["files"].push_back({{"path", f.path}, {"size", f.size}, {"sha256", f.sha256}});
  }
  return j;
}

}  // namespace sd::bank
