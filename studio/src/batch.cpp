#include "carousel/studio/batch.h"

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <map>
#include <sstream>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

using json = nlohmann::json;

// The fields of one CSV line (RFC 4180 quoting, within the line). \throw FormatError.
std::vector<std::string> CsvFields(const std::string& line, const std::filesystem::path& file,
                                   int line_number) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char ch = line[i];
    if (quoted) {
      if (ch == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        fields.back().push_back('"');
        ++i;
      } else if (ch == '"') {
        quoted = false;
      } else {
        fields.back().push_back(ch);
      }
    } else if (ch == '"') {
      quoted = true;
    } else if (ch == ',') {
      fields.emplace_back();
    } else {
      fields.back().push_back(ch);
    }
  }
  if (quoted) throw FormatError(file, "line " + std::to_string(line_number) + ": unclosed quote");
  for (std::string& f : fields) {
    const auto first = f.find_first_not_of(" \t");
    const auto last = f.find_last_not_of(" \t");
    f = first == std::string::npos ? std::string() : f.substr(first, last - first + 1);
  }
  return fields;
}

std::string CsvField(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string out = "\"";
  for (const char ch : text) {
    if (ch == '"') out.push_back('"');
    out.push_back(ch);
  }
  return out + "\"";
}

std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << value;
  return out.str();
}

// Double-quoted for YAML (JSON's string syntax is YAML's).
std::string YamlString(const std::string& text) { return json(text).dump(); }

}  // namespace

std::string ShellQuote(const std::string& text) {
  std::string out = "'";
  for (const char ch : text) {
    if (ch == '\'') {
      out += "'\\''";
    } else {
      out.push_back(ch);
    }
  }
  return out + "'";
}

std::vector<BatchItem> ReadCatalog(const std::filesystem::path& csv) {
  std::ifstream in(csv);
  if (!in) throw IoError(csv, "cannot read the catalog");
  std::vector<BatchItem> items;
  std::map<std::string, int> seen;  // SKU -> line
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    if (line[line.find_first_not_of(" \t")] == '#') continue;
    const std::vector<std::string> fields = CsvFields(line, csv, number);
    const std::string where = "line " + std::to_string(number) + ": ";
    if (fields.size() != 2)
      throw FormatError(csv, where + "expected 2 fields (SKU,session folder), got " +
                                 std::to_string(fields.size()));
    if (items.empty() && seen.empty() && fields[1] == "session") {
      seen[""] = number;  // the header
      continue;
    }
    if (fields[0].empty()) throw FormatError(csv, where + "empty SKU");
    if (fields[1].empty()) throw FormatError(csv, where + "empty session folder");
    if (const auto it = seen.find(fields[0]); it != seen.end())
      throw FormatError(
          csv, where + "SKU '" + fields[0] + "' is also on line " + std::to_string(it->second));
    seen[fields[0]] = number;
    std::filesystem::path session = fields[1];
    if (session.is_relative()) session = csv.parent_path() / session;
    items.push_back({fields[0], std::filesystem::absolute(session).lexically_normal()});
  }
  if (items.empty()) throw FormatError(csv, "the catalog lists no session");
  return items;
}

BatchItem BatchItemForSession(const std::filesystem::path& session) {
  BatchItem item;
  item.session = std::filesystem::absolute(session).lexically_normal();
  if (item.session.filename().empty()) item.session = item.session.parent_path();
  item.sku = item.session.filename().string();
  try {
    const json manifest = ParseJsonFile(item.session / kManifestName);
    const std::string product = manifest.value("product", std::string());
    if (!product.empty()) item.sku = product;
  } catch (const Error&) {
    // No readable manifest: the folder's name; the task will say what is wrong with it.
  }
  return item;
}

json BatchRecordToJson(const BatchRecord& r) {
  json j = {{"task", r.task},
            {"sku", r.sku},
            {"session", r.session.string()},
            {"status", r.status},
            {"exit_code", r.exit_code},
            {"error", r.error},
            {"faces", r.faces},
            {"texture_size", r.texture_size},
            {"held_out_psnr_db", nullptr},
            {"seconds", r.seconds},
            {"peak_mb", r.peak_mb},
            {"attempt", r.attempt},
            {"host", r.host},
            {"pid", r.pid},
            {"job", r.job},
            {"stages", r.stages}};
  if (r.held_out_psnr_db) j["held_out_psnr_db"] = *r.held_out_psnr_db;
  return j;
}

BatchRecord BatchRecordFromJson(const json& j, const std::filesystem::path& file) {
  BatchRecord r;
  try {
    r.task = j.at("task").get<int>();
    r.sku = j.at("sku").get<std::string>();
    r.session = j.at("session").get<std::string>();
    r.status = j.at("status").get<std::string>();
    r.exit_code = j.value("exit_code", -1);
    r.error = j.value("error", std::string());
    r.faces = j.value("faces", 0);
    r.texture_size = j.value("texture_size", 0);
    if (j.contains("held_out_psnr_db") && j["held_out_psnr_db"].is_number())
      r.held_out_psnr_db = j["held_out_psnr_db"].get<double>();
    r.seconds = j.value("seconds", 0.0);
    r.peak_mb = j.value("peak_mb", 0.0);
    r.attempt = j.value("attempt", 0);
    r.host = j.value("host", std::string());
    r.pid = j.value("pid", 0);
    r.job = j.value("job", std::string());
    r.stages = j.value("stages", std::string());
  } catch (const json::exception& e) {
    throw FormatError(file, std::string("malformed task record: ") + e.what());
  }
  return r;
}

void ReadModelFigures(BatchRecord* record) {
  const std::filesystem::path report = record->session / "model" / "report.json";
  if (!std::filesystem::is_regular_file(report)) return;
  try {
    const json j = ParseJsonFile(report);
    record->faces = j.value("faces", 0);
    record->texture_size = j.value("atlas_size", 0);
    const json::json_pointer psnr("/held_out/mean_psnr_db");
    if (j.contains(psnr) && j.at(psnr).is_number()) record->held_out_psnr_db = j.at(psnr);
  } catch (const Error&) {
    // A damaged report leaves the figures out; the task's status says whether it worked.
  }
}

void WriteBatchTasks(const std::filesystem::path& folder, const std::vector<BatchItem>& items) {
  std::error_code ec;
  std::filesystem::create_directories(folder / "results", ec);
  if (ec) throw IoError(folder, "cannot create the batch folder: " + ec.message());
  json tasks = json::array();
  for (const BatchItem& item : items)
    tasks.push_back({{"sku", item.sku}, {"session", item.session.string()}});
  WriteFileAtomic(folder / "tasks.json", tasks.dump(2) + "\n");
}

std::vector<BatchItem> ReadBatchTasks(const std::filesystem::path& folder) {
  const std::filesystem::path file = folder / "tasks.json";
  if (!std::filesystem::is_regular_file(file))
    throw IoError(file, "no batch here (`carousel batch --out` writes it)");
  const json j = ParseJsonFile(file);
  std::vector<BatchItem> items;
  try {
    for (const json& task : j)
      items.push_back({task.at("sku").get<std::string>(), task.at("session").get<std::string>()});
  } catch (const json::exception& e) {
    throw FormatError(file, std::string("malformed task list: ") + e.what());
  }
  return items;
}

std::filesystem::path BatchResultFile(const std::filesystem::path& folder, int task) {
  return folder / "results" / (std::to_string(task) + ".json");
}

BatchRecord ReadBatchResult(const std::filesystem::path& folder, int task, const BatchItem& item) {
  const std::filesystem::path file = BatchResultFile(folder, task);
  if (std::filesystem::is_regular_file(file)) {
    BatchRecord record = BatchRecordFromJson(ParseJsonFile(file), file);
    if (record.session == item.session) return record;
    // A record of an earlier batch in this folder with other sessions: not this task's.
  }
  BatchRecord record;
  record.task = task;
  record.sku = item.sku;
  record.session = item.session;
  return record;
}

void WriteBatchSummary(const std::filesystem::path& folder,
                       const std::vector<BatchRecord>& records) {
  std::ostringstream csv;
  csv << "task,sku,session,status,faces,texture_size,held_out_psnr_db,seconds,peak_mb,attempt,"
         "host,job,exit_code,error\n";
  json all = json::array();
  for (const BatchRecord& r : records) {
    csv << r.task << ',' << CsvField(r.sku) << ',' << CsvField(r.session.string()) << ','
        << r.status << ',' << r.faces << ',' << r.texture_size << ','
        << (r.held_out_psnr_db ? Fixed(*r.held_out_psnr_db, 2) : "") << ',' << Fixed(r.seconds, 2)
        << ',' << Fixed(r.peak_mb, 1) << ',' << r.attempt << ',' << CsvField(r.host) << ','
        << CsvField(r.job) << ',' << r.exit_code << ',' << CsvField(r.error) << '\n';
    all.push_back(BatchRecordToJson(r));
  }
  WriteFileAtomic(folder / "summary.csv", csv.str());
  WriteFileAtomic(folder / "summary.json", json{{"tasks", all}}.dump(2) + "\n");
}

std::string BatchTable(const std::vector<BatchRecord>& records) {
  std::size_t sku_width = 3;
  for (const BatchRecord& r : records) sku_width = std::max(sku_width, r.sku.size());
  sku_width = std::min<std::size_t>(sku_width, 32);
  std::ostringstream out;
  const auto row = [&](const std::string& sku, const std::string& status, const std::string& faces,
                       const std::string& texture, const std::string& psnr,
                       const std::string& seconds, const std::string& peak,
                       const std::string& note) {
    out << std::left << std::setw(static_cast<int>(sku_width)) << sku.substr(0, sku_width) << "  "
        << std::setw(9) << status << std::right << std::setw(7) << faces << std::setw(8) << texture
        << std::setw(8) << psnr << std::setw(8) << seconds << std::setw(8) << peak << "  " << note
        << '\n';
  };
  row("SKU", "status", "faces", "texture", "PSNR", "time s", "peak MB", "");
  std::map<std::string, int> counts;
  double seconds = 0.0;
  for (const BatchRecord& r : records) {
    ++counts[r.status];
    seconds += r.seconds;
    const bool ran = r.status == "done" || r.status == "failed";
    std::string note = r.error;
    if (note.size() > 100) note = note.substr(0, 97) + "...";
    if (r.attempt > 0)
      note.insert(0, "attempt " + std::to_string(r.attempt + 1) + (note.empty() ? "" : "; "));
    row(r.sku, r.status, r.faces > 0 ? std::to_string(r.faces) : "-",
        r.texture_size > 0 ? std::to_string(r.texture_size) : "-",
        r.held_out_psnr_db ? Fixed(*r.held_out_psnr_db, 2) : "-", ran ? Fixed(r.seconds, 1) : "-",
        ran && r.peak_mb > 0 ? Fixed(r.peak_mb, 0) : "-", note);
  }
  out << records.size() << (records.size() == 1 ? " session" : " sessions");
  for (const auto& [status, count] : counts) out << ", " << count << ' ' << status;
  out << "; " << Fixed(seconds, 1) << " s of processing\n";
  return out.str();
}

bool BatchExitIsFinal(int exit_code) {
  return exit_code == 0 || exit_code == 64 || exit_code == 65 || exit_code == 74;
}

std::string SbatchScript(const std::filesystem::path& folder, int count, const BatchJobOptions& o) {
  CAROUSEL_THROW_IF(count < 1, InvalidArgument, "a batch job needs at least one task");
  std::ostringstream s;
  s << "#!/bin/bash\n"
    << "# Written by `carousel batch --slurm`: one array task per session of " << folder.string()
    << "/tasks.json.\n"
    << "#SBATCH --job-name=" << o.name << '\n'
    << "#SBATCH --array=0-" << count - 1;
  if (o.max_parallel > 0) s << '%' << o.max_parallel;
  s << '\n'
    << "#SBATCH --requeue\n"
    << "#SBATCH --open-mode=append\n"
    << "#SBATCH --output=" << (folder / "logs" / "task-%a.out").string() << '\n'
    << "#SBATCH --cpus-per-task=" << o.cpus_per_task << '\n';
  if (o.memory_mb > 0) s << "#SBATCH --mem=" << o.memory_mb << "M\n";
  if (!o.partition.empty()) s << "#SBATCH --partition=" << o.partition << '\n';
  if (!o.time_limit.empty()) s << "#SBATCH --time=" << o.time_limit << '\n';
  s << "set -u\n"
    << "# The task's own log is <session>/batch.log; its record results/<task>.json.\n"
    << ShellQuote(o.executable.string()) << " --threads \"${SLURM_CPUS_PER_TASK:-"
    << o.cpus_per_task << "}\" batch task " << ShellQuote(folder.string())
    << " --index \"$SLURM_ARRAY_TASK_ID\"";
  for (const std::string& arg : o.process_args) s << ' ' << ShellQuote(arg);
  s << "\ncode=$?\n"
    << "# Done, or bad input a retry cannot mend (64 usage, 65 malformed file, 74 missing or\n"
    << "# unreadable file): the task ends. Anything else (a crash, a full disk, a lost device) is\n"
    << "# requeued up to " << o.retries << " times.\n"
    << "case $code in 0|64|65|74) exit $code ;; esac\n"
    << "if [ \"${SLURM_RESTART_COUNT:-0}\" -lt " << o.retries << " ]; then\n"
    << "  echo \"carousel batch: task $SLURM_ARRAY_TASK_ID failed with exit code $code; requeued "
       "(restart $(( ${SLURM_RESTART_COUNT:-0} + 1 )) of "
    << o.retries << ")\"\n"
    << "  scontrol requeue \"${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\"\n"
    << "fi\n"
    << "exit $code\n";
  return s.str();
}

std::string KubernetesManifest(const std::filesystem::path& folder,
                               const std::vector<BatchItem>& items, const BatchJobOptions& o) {
  CAROUSEL_THROW_IF(items.empty(), InvalidArgument, "a batch job needs at least one task");
  // The deepest folder holding the batch folder and every session.
  std::filesystem::path root = folder;
  const auto holds = [](const std::filesystem::path& parent, const std::filesystem::path& child) {
    auto p = parent.begin();
    auto c = child.begin();
    for (; p != parent.end(); ++p, ++c) {
      if (c == child.end() || *p != *c) return false;
    }
    return true;
  };
  for (const BatchItem& item : items) {
    while (!holds(root, item.session) && root.has_relative_path()) root = root.parent_path();
  }
  std::ostringstream s;
  s << "# Written by `carousel batch --k8s-manifest`: a Kubernetes Indexed Job, one index per\n"
    << "# session of " << folder.string() << "/tasks.json. kubectl apply -f <this file>\n"
    << "apiVersion: batch/v1\n"
    << "kind: Job\n"
    << "metadata:\n"
    << "  name: " << o.name << '\n'
    << "  labels:\n"
    << "    app.kubernetes.io/name: carousel\n"
    << "spec:\n"
    << "  completionMode: Indexed\n"
    << "  completions: " << items.size() << '\n'
    << "  parallelism: " << (o.max_parallel > 0 ? o.max_parallel : static_cast<int>(items.size()))
    << '\n'
    << "  backoffLimitPerIndex: " << o.retries << '\n'
    << "  maxFailedIndexes: " << items.size() << '\n'
    << "  podFailurePolicy:\n"
    << "    rules:\n"
    << "      # bad input (usage, malformed or missing files): a retry gives the same answer\n"
    << "      - action: FailIndex\n"
    << "        onExitCodes:\n"
    << "          containerName: carousel\n"
    << "          operator: In\n"
    << "          values: [64, 65, 74]\n"
    << "  template:\n"
    << "    metadata:\n"
    << "      labels:\n"
    << "        app.kubernetes.io/name: carousel\n"
    << "    spec:\n"
    << "      restartPolicy: Never\n"
    << "      containers:\n"
    << "        - name: carousel\n"
    << "          image: " << YamlString(o.image) << '\n'
    << "          # the index comes from $JOB_COMPLETION_INDEX, set by the Job controller\n"
    << "          command:\n";
  std::vector<std::string> command = {"carousel", "--threads", std::to_string(o.cpus_per_task),
                                      "batch",    "task",      folder.string()};
  command.insert(command.end(), o.process_args.begin(), o.process_args.end());
  for (const std::string& word : command) s << "            - " << YamlString(word) << '\n';
  s << "          resources:\n"
    << "            requests:\n"
    << "              cpu: " << YamlString(std::to_string(o.cpus_per_task)) << '\n';
  if (o.memory_mb > 0) {
    s << "              memory: " << YamlString(std::to_string(o.memory_mb) + "Mi") << '\n'
      << "            limits:\n"
      << "              memory: " << YamlString(std::to_string(o.memory_mb) + "Mi") << '\n';
  }
  s << "          volumeMounts:\n"
    << "            - name: sessions\n"
    << "              mountPath: " << YamlString(root.string()) << '\n'
    << "      volumes:\n"
    << "        - name: sessions\n"
    << "          persistentVolumeClaim:\n"
    << "            claimName: " << YamlString(o.volume_claim) << '\n';
  return s.str();
}

}  // namespace carousel::studio
