//! [`Tee`]: one stream of bytes written to several places (a recording
//! into its file and into a bag at once).

use std::io::Write;

/// Writes every byte to each of its writers, in order; the first error
/// ends the write.
pub struct Tee(pub Vec<Box<dyn Write + Send>>);

impl std::fmt::Debug for Tee {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tee({} writers)", self.0.len())
    }
}

impl Write for Tee {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        for w in &mut self.0 {
            w.write_all(buf)?;
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.iter_mut().try_for_each(|w| w.flush())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn every_writer_gets_every_byte() {
        let (a, b) = (Shared::default(), Shared::default());
        let mut tee = Tee(vec![Box::new(a.clone()), Box::new(b.clone())]);
        tee.write_all(b"CLSM").unwrap();
        tee.write_all(b"REC").unwrap();
        tee.flush().unwrap();
        assert_eq!(*a.0.lock().unwrap(), b"CLSMREC");
        assert_eq!(*b.0.lock().unwrap(), b"CLSMREC");
    }
}
