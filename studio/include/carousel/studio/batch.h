// Catalog-scale processing: many sessions processed as independent tasks, on this machine
// (`carousel batch`, N processes at once) or as a Slurm job array / Kubernetes Indexed Job
// (`carousel batch --slurm`, `--k8s-manifest`). What lives here is what every way of running
// shares: the catalog, the batch folder and its task list, one result record per task, the
// summary, and the job files a scheduler runs. Spawning and submitting are app/'s.
//
// The batch folder (--out) holds:
//   tasks.json          the sessions in task order: [{"sku", "session"}]; task i is entry i
//   results/<i>.json    task i's last attempt (BatchRecord), written by the task itself
//   summary.csv/.json   every task's record, written when a local batch ends or on `status`
//   job.sbatch, jobs.json, logs/   the Slurm job script, the submitted job ids, Slurm's output
// Each session's own log of its tasks is <session>/batch.log (appended, one header per attempt).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace carousel::studio {

// One product of a batch: its SKU and its session folder (absolute).
struct BatchItem {
  std::string sku;
  std::filesystem::path session;
};

// A catalog CSV: one "SKU,session folder" line per product, a header line allowed (its second
// field "session"), '#' comments and blank lines ignored; a relative folder is relative to the
// CSV's folder. Fields may be double-quoted ("a, b"). \throw FormatError naming the file and
// line (wrong field count, empty SKU, an SKU twice), IoError (unreadable).
std::vector<BatchItem> ReadCatalog(const std::filesystem::path& csv);

// A session given by its folder: the SKU is its manifest's product, else the folder's name.
BatchItem BatchItemForSession(const std::filesystem::path& session);

// What became of one task (the summary's row).
struct BatchRecord {
  int task = 0;
  std::string sku;
  std::filesystem::path session;
  // done, failed, running (its process is alive, or was killed before it could say: see
  // `carousel batch status`), pending, cancelled
  std::string status = "pending";
  int exit_code = -1;
  std::string error;  // the first line of the error, for a failed task
  int faces = 0;      // of the textured model (model/report.json)
  int texture_size = 0;
  std::optional<double> held_out_psnr_db;
  double seconds = 0.0;  // wall time of the task's last attempt
  double peak_mb = 0.0;  // its peak resident memory
  int attempt = 0;       // 0 first, 1 after one requeue, ...
  std::string host;
  int pid = 0;         // the task's process on `host`
  std::string job;     // the scheduler's task id ("12_3"), empty for a local batch
  std::string stages;  // "reconstruct ran, texture ran, publish current"
};

nlohmann::json BatchRecordToJson(const BatchRecord& record);
// \throw FormatError naming `file`.
BatchRecord BatchRecordFromJson(const nlohmann::json& j, const std::filesystem::path& file);

// The textured model's figures (faces, texture size, held-out PSNR) from the session's
// model/report.json into `record`; nothing when there is none.
void ReadModelFigures(BatchRecord* record);

// tasks.json in `folder` (created). \throw IoError.
void WriteBatchTasks(const std::filesystem::path& folder, const std::vector<BatchItem>& items);
// \throw IoError (missing), FormatError naming the file.
std::vector<BatchItem> ReadBatchTasks(const std::filesystem::path& folder);
std::filesystem::path BatchResultFile(const std::filesystem::path& folder, int task);
// The task's record if it wrote one, else a pending record for items[task].
BatchRecord ReadBatchResult(const std::filesystem::path& folder, int task, const BatchItem& item);

// summary.csv and summary.json in `folder`, atomically. \throw IoError.
void WriteBatchSummary(const std::filesystem::path& folder,
                       const std::vector<BatchRecord>& records);
// A table for the terminal: one row per task and a totals line.
std::string BatchTable(const std::vector<BatchRecord>& records);

// `text` single-quoted for sh (the job script's paths, squeue's arguments).
std::string ShellQuote(const std::string& text);

// How a scheduler runs the tasks.
struct BatchJobOptions {
  std::filesystem::path executable;  // the carousel program every node runs (absolute)
  int max_parallel = 0;              // tasks at once (0: as many as the cluster gives)
  int cpus_per_task = 2;
  int memory_mb = 0;  // per task (0: not requested)
  int retries = 2;    // a task failing for a reason a retry may mend is requeued this often
  std::string partition;
  std::string time_limit;  // per task, Slurm's format ("30:00"); empty: the partition's
  std::string name = "carousel-batch";
  std::vector<std::string> process_args;  // given to `process` (e.g. --faces 5000)
  // Kubernetes: the container image and the volume claim holding the sessions.
  std::string image = "carousel:latest";
  std::string volume_claim = "carousel-sessions";
};

// Exit codes after which a task is not retried: done (0), bad command line (64), malformed
// input (65), unreadable or missing files (74): a retry gives the same answer.
bool BatchExitIsFinal(int exit_code);

// The sbatch script of `count` tasks over `folder` (a job array 0..count-1, requeued on
// failure up to options.retries, Slurm's output in folder/logs).
std::string SbatchScript(const std::filesystem::path& folder, int count,
                         const BatchJobOptions& options);

// A Kubernetes Indexed Job (batch/v1) running the same tasks: completions = count, parallelism
// = max_parallel, a retry budget per index, bad-input exit codes failing their index at once,
// and one volume claim mounted at the deepest folder holding `folder` and every session (they
// keep their paths inside the containers).
std::string KubernetesManifest(const std::filesystem::path& folder,
                               const std::vector<BatchItem>& items, const BatchJobOptions& options);

}  // namespace carousel::studio
